#pragma once
// A recording's file while it is written, in either of its formats: SQLite (recording.db, the
// tables of Recording.cpp) or MCAP (.mcap, for Foxglove and every MCAP tool). The recording's
// writer thread, `cpm history export` and the reading of an MCAP file (which puts it into an
// SQLite database in memory, so that every reader of recordings reads it) all write through it.
//
// MCAP as cpm writes it (DESIGN: one Schema per IDL type, encoding omgidl, one self-contained
// IDL text; one Channel per topic, encoding cdr, metadata cpm.type, cpm.keyed, cpm.qos;
// log_time = commit time, publish_time = the data time; Metadata cpm.recording, cpm.idl and,
// at the close, cpm.recording_end). What MCAP has no field for goes into private records
// (op 0x80 and up, which the spec leaves to applications and viewers skip), in the chunk
// before the messages they concern:
//   0x80 cpm.object   an object's info block (JSON), before its first sample
//   0x81 cpm.sample   the next message's oid, valid_after, source time, lost_before and data
//                     time (five little-endian uint64)
//   0x82 cpm.deleted  an object's deletion time
// A message's channel sequence also skips the samples lost before it. A message without a
// cpm.sample record before it is derived for viewers (with foxglove_3d, the cars' poses as
// foxglove::FrameTransform on /tf) and is no sample of the run: reading the file skips it.
#include <cpm/Error.hpp>
#include <cpm/rtdb/Store.hpp>

#include <cstdint>
#include <map>
#include <memory>
#include <string>

struct sqlite3;

namespace cpm::rtdb {

/// What a recording's meta table (an MCAP file's cpm.recording) says it is.
inline constexpr const char* kRecordingFormat = "cpm-recording";
inline constexpr const char* kRecordingVersion = "1";

enum class RecordingFormat { sqlite, mcap };

/// The format a recording at `path` is written in: MCAP for the extension .mcap, else SQLite;
/// `format` ("sqlite", "mcap", "" for by extension) overrides it. Throws cpm::Error naming an
/// unknown format.
RecordingFormat recording_format(const std::string& path, const std::string& format = "");

/// One sample as it is recorded.
struct RecordedSample
{
    uint64_t commit_ns = 0, data_ns = 0, valid_after_ns = 0, source_ns = 0, lost_before = 0;
    const uint8_t* payload = nullptr;
    size_t size = 0;
};

class RecordingFile
{
public:
    virtual ~RecordingFile() = default;
    virtual void add_object(const ObjectInfo& info) = 0;
    virtual void add_sample(Oid oid, const RecordedSample& s) = 0;
    virtual void delete_object(Oid oid, uint64_t deleted_ns) = 0;
    /// A Metadata record (MCAP; SQLite files have none).
    virtual void add_metadata(const std::string& name, const std::map<std::string, std::string>& values) { (void)name, (void)values; }
    /// What was added since the last commit is in the file (SQLite: one transaction; MCAP: the
    /// open chunk is written once it is full or a second old; a file of size
    /// limit max_bytes has chunks of a sixteenth of it).
    virtual void commit() = 0;
    /// The samples in the file so far (an MCAP file's open chunk is not yet in it).
    virtual uint64_t samples_in_file() const = 0;
    /// The file's size so far.
    virtual uint64_t bytes() const = 0;
    /// Writes the end (`end`: ended_ns, samples, dropped) and closes the file; what it cannot
    /// write after a failure is left out (what was committed stays readable).
    virtual void finish(const std::map<std::string, std::string>& end) = 0;
};

/// What the file's writes throw when its size limit or the disk is reached.
struct RecordingFull : Error
{
    using Error::Error;
};

/// A new recording file at `path` (it must not exist), with its meta (format, version, name,
/// host, started_ns) and the IDL texts it carries. Throws cpm::Error naming the file.
/// `max_bytes` (0: none) ends it as a full disk would.
/// `foxglove_3d` (MCAP): the cars' poses also as foxglove::FrameTransform messages on /tf.
std::unique_ptr<RecordingFile> create_recording_file(const std::string& path, RecordingFormat format,
                                                     const std::map<std::string, std::string>& meta,
                                                     const std::map<std::string, std::string>& idl, uint64_t max_bytes = 0,
                                                     bool foxglove_3d = false);

/// The same as an SQLite database already open (an empty one), for reading an MCAP file.
std::unique_ptr<RecordingFile> recording_tables_in(sqlite3* db, const std::map<std::string, std::string>& meta,
                                                   const std::map<std::string, std::string>& idl);

/// Copies an MCAP file into `db` (empty, open) as a recording's tables: cpm's own files whole,
/// another's (no cpm records) one object per channel and key. A file damaged or cut short is
/// copied up to the damage, which its meta's "damage" names. Throws cpm::Error naming the file
/// when it is no MCAP file.
void copy_mcap_into(const std::string& path, sqlite3* db);

/// One IDL text for `type_name` out of `sources` (file name → text): the files it includes
/// first, each once, then its own, without preprocessor lines; "" when no file defines it.
std::string self_contained_idl(const std::map<std::string, std::string>& sources, const std::string& type_name);

}  // namespace cpm::rtdb
