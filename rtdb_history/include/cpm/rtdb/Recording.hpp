#pragma once
// A recording: everything a history service ingests, kept on disk in one SQLite file
// (recording.db), and read back into a Store that answers the same questions as the live one.
//
// Writing: a RecordingWriter is an IngestSink (ServiceOptions::sinks). The ingest only copies
// each sample into a queue; a writer thread puts the queue into the file in batched
// transactions (WAL), so the ingest never waits on the disk. The file holds every object's info
// block, every sample (commit, data, valid_after and source times, the samples lost before it,
// the payload as received) and the IDL text of every type cpm knows, so it is read without the
// build that made it. When the disk is full (or --record-max-bytes is reached) the recording
// stops with an error naming the file; what was written stays, the live service goes on.
//
// Reading: load_recording() puts the file back into a Store under the oids and commit times it
// had, keeping everything (no window). A damaged or truncated file loads up to the damage and
// says where it stopped.
#include <cpm/HistoryClient.hpp>
#include <cpm/rtdb/IngestSink.hpp>
#include <cpm/rtdb/Store.hpp>

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>
#include <utility>
#include <vector>

struct sqlite3;

namespace cpm::rtdb {

class IdlDecoder;
class RecordingFile;

struct RecordingOptions
{
    std::string name;  ///< the run's name, kept in the file's meta table
    /// The file stops growing here: the recording ends with an error, as on a full disk. 0: no
    /// limit but the disk's.
    uint64_t max_bytes = 0;
    /// The ingest drops samples (counted, and said) once this much payload waits for the disk.
    uint64_t max_queued_bytes = 256ull << 20;
    /// A batch is written at least this often.
    uint64_t flush_period_ns = 100'000'000ull;
    /// "sqlite" or "mcap"; "" (the default): MCAP for a file named *.mcap, else SQLite.
    std::string format;
    /// MCAP: the cars' poses also as foxglove::FrameTransform on /tf (Foxglove's 3D panel).
    bool foxglove_3d = false;
    /// Split (0: never): a new file once the current one holds this many bytes or is this old.
    /// The files are <stem>_000<ext>, <stem>_001<ext>, … beside the path given; each stands alone
    /// (the IDL, every living object's info block and the newest sample of each transient-local
    /// topic again at its start, marked as carried), and a folder of them reads as one recording.
    uint64_t split_bytes = 0;
    uint64_t split_ns = 0;
    /// With a split: the oldest files are deleted while all of them hold more (0: none is).
    uint64_t max_total_bytes = 0;
};

struct RecordingCounters
{
    uint64_t queued = 0;   ///< samples handed to the recording
    uint64_t written = 0;  ///< samples committed to the file
    uint64_t dropped = 0;  ///< samples that never reached the file (queue full, or after a failure)
    uint64_t waiting = 0;  ///< samples queued that the writer's thread has not taken up yet (how far it is behind)
    bool failed = false;
    std::string error;     ///< why the recording stopped, naming the file
};

class RecordingWriter final : public IngestSink
{
public:
    /// Creates the file (it must not exist: a recording is never overwritten) and starts the
    /// writer thread. Throws cpm::Error naming the file when it cannot be made.
    explicit RecordingWriter(std::string path, RecordingOptions options = {});
    /// close().
    ~RecordingWriter() override;
    RecordingWriter(const RecordingWriter&) = delete;
    RecordingWriter& operator=(const RecordingWriter&) = delete;

    void object_added(const ObjectInfo& info) override;
    void sample_committed(Oid oid, const Incoming& sample, uint64_t commit_ns) override;
    void object_deleted(Oid oid, uint64_t deleted_ns) override;

    /// Writes what is queued, the end time and an index, and closes the file as one
    /// self-contained file. Idempotent.
    void close();
    RecordingCounters counters() const;
    /// The path given; with a split, each file's name (the newest last, deleted ones left out).
    const std::string& path() const { return path_; }
    std::vector<std::string> files() const;

private:
    struct Event;
    void run();
    bool write(std::deque<Event>& batch);
    void fail(const std::string& why);

    std::string path_;
    RecordingOptions options_;
    std::unique_ptr<RecordingFile> file_;
    mutable std::mutex mutex_;
    std::condition_variable cv_;
    std::deque<Event> queue_;
    uint64_t queued_bytes_ = 0;
    bool closing_ = false, failed_ = false, closed_ = false;
    RecordingCounters counters_;
    uint64_t started_ns_ = 0;
    uint64_t added_ = 0;  // samples handed to the file (its writer thread's)
    // Splitting (the writer thread's): the parts so far, when the current one began, and what the
    // next one carries at its start.
    std::string part_path(size_t part) const;
    void split_if_due();
    void keep_if_transient_local(const Event& e);
    std::vector<std::string> parts_;
    size_t part_count_ = 1;  // parts begun, deleted ones too: the next one's number
    uint64_t part_started_ns_ = 0;
    std::map<Oid, ObjectInfo> living_;
    struct Kept
    {
        uint64_t commit_ns, data_ns, valid_after_ns, source_ns;
        std::vector<uint8_t> payload;
    };
    std::map<Oid, Kept> newest_kept_;  // the newest sample of each transient-local object
    uint64_t written_before_ = 0;      // samples in the finished parts (carried ones not counted)
    uint64_t carried_ = 0;             // samples the current part carries at its start
    std::thread thread_;
};

/// A recording read back.
struct LoadedRecording
{
    std::unique_ptr<Store> store;
    std::string name;
    uint64_t started_ns = 0;
    uint64_t ended_ns = 0;   ///< the clean end, else the newest commit time in the file
    bool complete = false;   ///< closed cleanly and read to the end
    uint64_t samples = 0;    ///< samples loaded
    std::string warning;     ///< why the load stopped early or the file was not closed ("" if neither)
    /// The recording's own types (the IDL text it carries); null when it holds none.
    std::shared_ptr<const IdlDecoder> types;
    std::map<std::string, std::string> idl;  ///< IDL file name → text
};

/// Reads a recording. Throws cpm::Error naming the file when it is not one (missing, not
/// SQLite, no cpm tables); a file damaged part way loads up to the damage (see warning).
LoadedRecording load_recording(const std::string& path);

/// A recording's clocks, read without loading it. Commits are the recorder's wall clock; data
/// times (create_stamp) are the run's own clock: the lab's, from 0, in a simulated run.
struct RunClock
{
    uint64_t started_ns = 0, ended_ns = 0;         ///< by commit: the start, the end (or newest commit)
    uint64_t data_first_ns = 0, data_last_ns = 0;  ///< the data times of its stamped samples
    bool lab_clock = false;                        ///< data times are a simulated lab clock from 0
};
/// Throws as load_recording.
RunClock recording_clock(const std::string& path);

/// A time flag's value (`--time`, `--from`, …) against a recording, as a commit time, or a data
/// time when `by_data`: a time into the run on its own clock ("20s": lab time in a simulated
/// run, since the start in a real one), relative to its end ("-2s", "now": the end of the clock
/// asked for), or absolute (ns, ISO-8601). Throws cpm::cli::UsageError naming the flag.
uint64_t recording_time(const std::string& path, const RunClock& clock, const std::string& flag, const std::string& text, bool by_data);

/// Whether `text` is a time into a run ("20s", "1.5s", "90s": a duration without a sign).
bool is_time_into_run(const std::string& text);

/// What `cpm history --file REC export --mcap|--sqlite OUT` copies.
struct ExportOptions
{
    std::string format;               ///< "sqlite", "mcap", "" for by OUT's extension
    std::vector<std::string> topics;  ///< none: every topic
    uint64_t from_ns = 0, to_ns = UINT64_MAX;  ///< the samples of [from, to)
    bool by_data = false;             ///< from/to are data times (else commit times)
    bool foxglove_3d = false;         ///< MCAP: the cars' poses also as foxglove::FrameTransform on /tf
    /// Metadata records for an MCAP file (name → values; cpm.run: the scenario and summary).
    std::map<std::string, std::map<std::string, std::string>> metadata;
};

struct ExportCounts
{
    uint64_t objects = 0, samples = 0;
};

/// Copies a recording (SQLite or MCAP) into a new file `out` (SQLite or MCAP): its meta and IDL,
/// the objects of the topics asked for (every process too) and their samples in commit order,
/// byte for byte with every time. Throws cpm::Error naming the file (`out` exists already, a
/// topic the recording does not hold, a write that fails: then `out` is removed).
ExportCounts export_recording(const std::string& path, const std::string& out, const ExportOptions& options);

/// A HistoryClient's backend answering from a loaded recording as the live service answers
/// (the kinds that wait answer at once: nothing new comes to a finished run).
/// HistoryClient::open_recording(path) is load_recording and this in one.
std::unique_ptr<cpm::HistoryBackend> recording_backend(std::shared_ptr<const LoadedRecording> recording);

}  // namespace cpm::rtdb
