#pragma once
// cpm::rtdb::mcap — MCAP files (https://mcap.dev), the format Foxglove and Lichtblick open,
// written and read by cpm's own code (no MCAP package is in Debian). Written as the spec's
// "indexed" layout: the data in chunks (uncompressed), a Message Index after each chunk, then
// a summary with every Schema and Channel, Statistics, Metadata Indexes and Chunk Indexes, and
// a Summary Offset per group, so a viewer can seek. Every CRC is computed (CRC-32, as zlib).
//
//   mcap::Writer w("run.mcap", "cpm 1.0");
//   const auto schema = w.add_schema("VehicleState", "omgidl", idl_text);
//   const auto channel = w.add_channel(schema, "vehicleState", "cdr", {{"cpm.keyed", "true"}});
//   w.write(channel, log_time, publish_time, payload.data(), payload.size());
//   w.close();
//
// Reader reads such a file back (any valid MCAP file with uncompressed chunks): its schemas,
// channels, metadata and messages in file order, checking every CRC and record length.
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace cpm::rtdb::mcap {

/// CRC-32 (ISO-HDLC, as zlib's crc32), continued from `crc` (0 to start).
uint32_t crc32(const uint8_t* data, size_t size, uint32_t crc = 0);

struct Schema
{
    uint16_t id = 0;
    std::string name, encoding;
    std::string data;
};

struct Channel
{
    uint16_t id = 0;
    uint16_t schema_id = 0;
    std::string topic, message_encoding;
    std::map<std::string, std::string> metadata;
};

struct Message
{
    uint16_t channel_id = 0;
    uint32_t sequence = 0;
    uint64_t log_time = 0, publish_time = 0;
    std::vector<uint8_t> data;
};

/// A private record (op >= 0x80) as read, with where it stood among the messages.
struct Private
{
    uint8_t op = 0;
    std::string body;
    size_t before_message = 0;  ///< the number of messages read before it
};

struct Metadata
{
    std::string name;
    std::map<std::string, std::string> values;
};

class Writer
{
public:
    /// A new file at `path` (an existing one is refused); chunks of about `chunk_size` bytes; a
    /// chunk that would take the file past `max_bytes` (0: no limit) is refused, and so is a
    /// chunk the disk has no room for: the file then ends with the chunks before it, and
    /// close() still writes a valid file of those. Throws cpm::Error naming the file when it
    /// cannot be written.
    Writer(const std::string& path, const std::string& library, size_t chunk_size = 1 << 20, uint64_t max_bytes = 0);
    ~Writer();  ///< closes, as close() (errors then only go to stderr)
    Writer(const Writer&) = delete;
    Writer& operator=(const Writer&) = delete;

    uint16_t add_schema(const std::string& name, const std::string& encoding, const std::string& data);
    /// schema_id 0: a channel without a schema (its messages' type is unknown).
    uint16_t add_channel(uint16_t schema_id, const std::string& topic, const std::string& message_encoding,
                         const std::map<std::string, std::string>& metadata = {});
    /// One message; log_time is what viewers order and seek by. `sequence` defaults to the
    /// channel's count so far (a gap tells a reader that messages were lost before this one).
    /// Throws cpm::Error for an unknown channel or a failed write.
    void write(uint16_t channel_id, uint64_t log_time, uint64_t publish_time, const uint8_t* data, size_t size,
               std::optional<uint32_t> sequence = std::nullopt);
    /// A private record (op 0x80 to 0xFF, which the spec leaves to applications and readers
    /// skip) into the open chunk, before the messages written after it.
    void write_private(uint8_t op, const std::string& body);
    /// Writes the open chunk and hands the file to the kernel: what was written so far survives
    /// the process being killed (a reader reads the file up to its last chunk).
    void flush();
    void add_metadata(const std::string& name, const std::map<std::string, std::string>& values);
    /// Writes the last chunk, the summary and the footer. Throws cpm::Error when the file cannot
    /// be finished.
    void close();

    /// The messages in the file's chunks so far (not those of the open chunk).
    uint64_t messages() const { return message_count_; }
    /// The file's size so far (the open chunk not counted).
    uint64_t bytes() const { return offset_; }
    /// The messages of one channel in the file's chunks so far.
    uint64_t channel_messages(uint16_t id) const
    {
        const auto it = channel_counts_.find(id);
        return it == channel_counts_.end() ? 0 : it->second;
    }

private:
    void flush_chunk();
    void finish();
    void drop_chunk();
    void put(const std::string& bytes);

    int fd_ = -1;
    std::string path_;
    size_t chunk_size_;
    uint64_t max_bytes_;
    uint64_t offset_ = 0;        // bytes written so far
    uint64_t reserved_end_ = 0;  // the disk's room taken (fallocate) up to here: the last chunk and the summary after it
    bool reserve_ = true;        // false where the file system has no fallocate
    uint32_t data_crc_ = 0;      // over the data section so far
    bool in_data_ = true;        // still writing the data section
    bool closed_ = false;
    std::vector<Schema> schemas_;
    std::vector<Channel> channels_;
    std::vector<Metadata> metadata_;
    std::vector<std::pair<uint64_t, uint64_t>> metadata_offsets_;  // offset, length of each Metadata record
    // The open chunk: its records, times and each channel's (log_time, offset in the chunk).
    std::string chunk_;
    uint64_t chunk_start_ = UINT64_MAX, chunk_end_ = 0;
    std::map<uint16_t, std::vector<std::pair<uint64_t, uint64_t>>> chunk_index_;
    std::vector<bool> schema_in_chunk_, channel_in_chunk_;
    std::string chunk_indexes_;  // the summary's Chunk Index records
    uint64_t chunk_count_ = 0;
    uint64_t message_count_ = 0, message_start_ = UINT64_MAX, message_end_ = 0;
    std::map<uint16_t, uint64_t> channel_counts_;
    std::map<uint16_t, uint32_t> sequences_;
};

/// A file read back: every record checked (lengths, CRCs of the chunks, the data section and the
/// summary); the summary's Chunk Indexes and Statistics kept for tests and tools.
struct File
{
    std::string profile, library;
    std::map<uint16_t, Schema> schemas;
    std::map<uint16_t, Channel> channels;
    std::vector<Message> messages;  ///< in file order
    std::vector<Metadata> metadata;
    std::vector<Private> privates;  ///< in file order
    uint64_t chunk_count = 0;       ///< chunks in the data section
    uint64_t chunk_indexes = 0;     ///< Chunk Index records in the summary
    uint64_t message_indexes = 0;   ///< Message Index records after the chunks
    uint64_t summary_start = 0;     ///< from the footer (0: no summary)
    /// Statistics' message count and per-channel counts (empty without Statistics).
    uint64_t statistics_messages = 0;
    std::map<uint16_t, uint64_t> statistics_channel_counts;
    /// With Damage::keep_what_reads: why the read stopped before the file's end ("" when it did
    /// not); the messages of every chunk before the damage are read, none of the damaged one.
    std::string damage;
};

enum class Damage { refuse, keep_what_reads };

/// Whether the file starts with MCAP's magic.
bool is_mcap(const std::string& path);

/// Reads and checks an MCAP file; throws cpm::Error naming the file, the byte offset and what is
/// wrong (bad magic, a record cut short, a CRC that does not match, a compressed chunk). With
/// Damage::keep_what_reads a file cut short or damaged after its header (a writer killed) reads
/// up to the damage, which File::damage names.
File read(const std::string& path, Damage damage = Damage::refuse);

}  // namespace cpm::rtdb::mcap
