#include <cpm/rtdb/Mcap.hpp>

#include <cpm/Error.hpp>

#include <array>
#include <cstdio>
#include <cstring>
#include <fcntl.h>
#include <fstream>
#include <iterator>
#include <unistd.h>

namespace cpm::rtdb::mcap {

namespace {

constexpr char kMagic[] = "\x89MCAP0\r\n";
constexpr size_t kMagicSize = 8;

enum Op : uint8_t {
    header = 0x01, footer = 0x02, schema = 0x03, channel = 0x04, message = 0x05, chunk = 0x06, message_index = 0x07,
    chunk_index = 0x08, attachment = 0x09, attachment_index = 0x0A, statistics = 0x0B, metadata = 0x0C, metadata_index = 0x0D,
    summary_offset = 0x0E, data_end = 0x0F,
};

const std::array<uint32_t, 256>& crc_table()
{
    static const auto table = [] {
        std::array<uint32_t, 256> t{};
        for (uint32_t i = 0; i < 256; ++i) {
            uint32_t c = i;
            for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
            t[i] = c;
        }
        return t;
    }();
    return table;
}

/// Little-endian encoding of the spec's field types.
struct Out
{
    std::string b;
    Out& u8(uint8_t v) { b.push_back(char(v)); return *this; }
    Out& u16(uint16_t v) { return le(v, 2); }
    Out& u32(uint32_t v) { return le(v, 4); }
    Out& u64(uint64_t v) { return le(v, 8); }
    Out& str(const std::string& s) { u32(uint32_t(s.size())); b += s; return *this; }
    Out& raw(const std::string& s) { b += s; return *this; }
    Out& string_map(const std::map<std::string, std::string>& m)
    {
        Out body;
        for (const auto& [k, v] : m) body.str(k).str(v);
        return u32(uint32_t(body.b.size())).raw(body.b);
    }
    Out& offsets_map(const std::map<uint16_t, uint64_t>& m)
    {
        Out body;
        for (const auto& [k, v] : m) body.u16(k).u64(v);
        return u32(uint32_t(body.b.size())).raw(body.b);
    }
    Out& le(uint64_t v, int n)
    {
        for (int i = 0; i < n; ++i) b.push_back(char((v >> (8 * i)) & 0xFF));
        return *this;
    }
};

std::string record(uint8_t op, const std::string& body)
{
    Out o;
    o.u8(op).u64(body.size()).raw(body);
    return o.b;
}

std::string schema_record(const Schema& s) { return record(schema, Out().u16(s.id).str(s.name).str(s.encoding).str(s.data).b); }
std::string channel_record(const Channel& c)
{
    return record(channel, Out().u16(c.id).u16(c.schema_id).str(c.topic).str(c.message_encoding).string_map(c.metadata).b);
}

}  // namespace

uint32_t crc32(const uint8_t* data, size_t size, uint32_t crc)
{
    const auto& t = crc_table();
    crc = ~crc;
    for (size_t i = 0; i < size; ++i) crc = t[(crc ^ data[i]) & 0xFF] ^ (crc >> 8);
    return ~crc;
}

static uint32_t crc_of(const std::string& s, uint32_t crc = 0) { return crc32(reinterpret_cast<const uint8_t*>(s.data()), s.size(), crc); }

// ---- Writer -------------------------------------------------------------------------------------

Writer::Writer(const std::string& path, const std::string& library, size_t chunk_size, uint64_t max_bytes)
    : path_(path), chunk_size_(chunk_size), max_bytes_(max_bytes)
{
    fd_ = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
    if (fd_ < 0) throw cpm::Error("mcap: cannot make " + path + ": " + std::strerror(errno) + (errno == EEXIST ? " (never overwritten)" : ""));
    try {
        put(std::string(kMagic, kMagicSize) + record(header, Out().str("").str(library).b));
    } catch (...) {
        ::close(fd_);
        fd_ = -1;
        throw;
    }
}

Writer::~Writer()
{
    try {
        close();
    } catch (const std::exception& e) {
        std::fprintf(stderr, "%s\n", e.what());
    }
}

void Writer::put(const std::string& bytes)
{
    for (size_t done = 0; done < bytes.size();) {
        const ssize_t n = ::write(fd_, bytes.data() + done, bytes.size() - done);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) {
            // What did not fit is taken back: the file ends with whole records, and close() can
            // still write the summary (the space of the record cut short is free again).
            const std::string why = std::strerror(n < 0 ? errno : ENOSPC);
            (void)!::ftruncate(fd_, off_t(offset_));
            (void)::lseek(fd_, off_t(offset_), SEEK_SET);
            throw cpm::Error("mcap: cannot write " + path_ + ": " + why);
        }
        done += size_t(n);
    }
    if (in_data_) data_crc_ = crc_of(bytes, data_crc_);  // the data section: from the magic to Data End
    offset_ += bytes.size();
}

uint16_t Writer::add_schema(const std::string& name, const std::string& encoding, const std::string& data)
{
    schemas_.push_back({uint16_t(schemas_.size() + 1), name, encoding, data});
    schema_in_chunk_.push_back(false);
    return schemas_.back().id;
}

uint16_t Writer::add_channel(uint16_t schema_id, const std::string& topic, const std::string& message_encoding,
                             const std::map<std::string, std::string>& metadata)
{
    if (schema_id > schemas_.size()) throw cpm::Error("mcap: channel " + topic + ": no schema " + std::to_string(schema_id));
    channels_.push_back({uint16_t(channels_.size()), schema_id, topic, message_encoding, metadata});
    channel_in_chunk_.push_back(false);
    return channels_.back().id;
}

void Writer::write(uint16_t channel_id, uint64_t log_time, uint64_t publish_time, const uint8_t* data, size_t size,
                   std::optional<uint32_t> sequence)
{
    if (channel_id >= channels_.size()) throw cpm::Error("mcap: no channel " + std::to_string(channel_id));
    const Channel& c = channels_[channel_id];
    // A chunk holds the schema and channel of its messages before them (for streaming readers).
    if (c.schema_id != 0 && !schema_in_chunk_[c.schema_id - 1]) {  // 0: a channel without a schema
        chunk_ += schema_record(schemas_[c.schema_id - 1]);
        schema_in_chunk_[c.schema_id - 1] = true;
    }
    if (!channel_in_chunk_[channel_id]) {
        chunk_ += channel_record(c);
        channel_in_chunk_[channel_id] = true;
    }
    chunk_index_[channel_id].emplace_back(log_time, chunk_.size());
    Out m;
    uint32_t& next = sequences_[channel_id];
    if (sequence) next = *sequence;
    m.u16(channel_id).u32(next++).u64(log_time).u64(publish_time).raw(std::string(reinterpret_cast<const char*>(data), size));
    chunk_ += record(message, m.b);
    chunk_start_ = std::min(chunk_start_, log_time);
    chunk_end_ = std::max(chunk_end_, log_time);

    if (chunk_.size() >= chunk_size_) flush_chunk();
}

void Writer::write_private(uint8_t op, const std::string& body)
{
    if (op < 0x80) throw cpm::Error("mcap: op " + std::to_string(op) + " is the spec's, not a private one");
    chunk_ += record(op, body);
    if (chunk_.size() >= chunk_size_) flush_chunk();
}

void Writer::flush()
{
    flush_chunk();
}

void Writer::flush_chunk()
{
    if (chunk_.empty()) return;
    const uint64_t chunk_offset = offset_;
    // A chunk of private records only (objects, deletions) has no message time: 0 to 0.
    const uint64_t start = chunk_index_.empty() ? 0 : chunk_start_, end = chunk_index_.empty() ? 0 : chunk_end_;
    Out body;
    body.u64(start).u64(end).u64(chunk_.size()).u32(crc_of(chunk_)).str("").u64(chunk_.size()).raw(chunk_);
    const std::string chunk_record = record(chunk, body.b);
    // Its Message Indexes follow it: offsets of each channel's messages in the chunk.
    const uint64_t indexes_offset = chunk_offset + chunk_record.size();
    std::map<uint16_t, uint64_t> index_offsets;
    std::string indexes;
    for (const auto& [id, entries] : chunk_index_) {
        Out e;
        for (const auto& [t, at] : entries) e.u64(t).u64(at);
        index_offsets[id] = indexes_offset + indexes.size();
        indexes += record(message_index, Out().u16(id).u32(uint32_t(e.b.size())).raw(e.b).b);
    }
    // Room is kept for what close() writes after it: the summary (the schemas and channels
    // again, the chunk indexes, this chunk's among them, statistics, metadata indexes, offsets),
    // the footer and a last Metadata record or two.
    uint64_t summary_room = chunk_indexes_.size() + 2048 + 64 * (channels_.size() + metadata_.size());
    for (const auto& x : schemas_) summary_room += schema_record(x).size();
    for (const auto& x : channels_) summary_room += channel_record(x).size();
    if (max_bytes_ && offset_ + chunk_record.size() + indexes.size() + summary_room > max_bytes_) {
        drop_chunk();
        throw cpm::Error("mcap: " + path_ + " reached its size limit of " + std::to_string(max_bytes_) + " bytes");
    }
    // The disk's room for it and for the summary after it, taken before the chunk is written
    // (allocated past the file's end): a disk that fills refuses this chunk here, while the
    // room taken with the chunk before is still there for close().
    const uint64_t room_end = offset_ + chunk_record.size() + indexes.size() + summary_room;
    if (room_end > reserved_end_ && reserve_) {
        if (::fallocate(fd_, FALLOC_FL_KEEP_SIZE, off_t(offset_), off_t(room_end - offset_)) == 0) {
            reserved_end_ = room_end;
        } else if (errno == ENOSPC || errno == EFBIG || errno == EDQUOT) {
            const std::string why = std::strerror(errno);
            drop_chunk();
            throw cpm::Error("mcap: cannot write " + path_ + ": " + why);
        } else {
            reserve_ = false;  // a file system without fallocate: put() takes back what does not fit
        }
    }
    // The chunk and its indexes in one write: both in the file, or neither (put takes back
    // what did not fit).
    try {
        put(chunk_record + indexes);
    } catch (const cpm::Error&) {
        drop_chunk();
        throw;
    }
    // Its messages count once the chunk is in the file.
    for (const auto& [id, entries] : chunk_index_) {
        message_count_ += entries.size();
        channel_counts_[id] += entries.size();
    }
    if (!chunk_index_.empty()) {
        message_start_ = std::min(message_start_, chunk_start_);
        message_end_ = std::max(message_end_, chunk_end_);
    }
    Out ci;
    ci.u64(start).u64(end).u64(chunk_offset).u64(chunk_record.size()).offsets_map(index_offsets).u64(indexes.size()).str("")
        .u64(chunk_.size()).u64(chunk_.size());
    chunk_indexes_ += record(chunk_index, ci.b);
    ++chunk_count_;
    drop_chunk();
}

void Writer::drop_chunk()
{
    chunk_.clear();
    chunk_index_.clear();
    chunk_start_ = UINT64_MAX;
    chunk_end_ = 0;
    std::fill(schema_in_chunk_.begin(), schema_in_chunk_.end(), false);
    std::fill(channel_in_chunk_.begin(), channel_in_chunk_.end(), false);
}

void Writer::add_metadata(const std::string& name, const std::map<std::string, std::string>& values)
{
    flush_chunk();  // a Metadata record lies outside chunks
    const std::string r = record(metadata, Out().str(name).string_map(values).b);
    const uint64_t at = offset_;
    put(r);  // indexed once it is in the file
    metadata_.push_back({name, values});
    metadata_offsets_.emplace_back(at, r.size());
}

void Writer::close()
{
    if (closed_ || fd_ < 0) return;
    closed_ = true;
    try {
        finish();
    } catch (...) {
        ::close(fd_);
        fd_ = -1;
        throw;
    }
}

void Writer::finish()
{
    try {
        flush_chunk();
    } catch (const cpm::Error&) {
        // The last chunk did not fit (its size limit, a full disk): the file ends before it.
    }
    put(record(data_end, Out().u32(data_crc_).b));
    in_data_ = false;
    const uint64_t summary_start = offset_;
    std::string summary;
    std::vector<std::tuple<uint8_t, uint64_t, uint64_t>> groups;
    auto group = [&](uint8_t op, const std::string& records) {
        if (records.empty()) return;
        groups.emplace_back(op, summary_start + summary.size(), records.size());
        summary += records;
    };
    std::string s, c, m;
    for (const auto& x : schemas_) s += schema_record(x);
    for (const auto& x : channels_) c += channel_record(x);
    group(schema, s);
    group(channel, c);
    Out stats;
    stats.u64(message_count_).u16(uint16_t(schemas_.size())).u32(uint32_t(channels_.size())).u32(0).u32(uint32_t(metadata_.size()))
        .u32(uint32_t(chunk_count_)).u64(message_count_ ? message_start_ : 0).u64(message_end_).offsets_map(channel_counts_);
    group(statistics, record(statistics, stats.b));
    for (size_t i = 0; i < metadata_.size(); ++i) {
        m += record(metadata_index, Out().u64(metadata_offsets_[i].first).u64(metadata_offsets_[i].second).str(metadata_[i].name).b);
    }
    group(metadata_index, m);
    group(chunk_index, chunk_indexes_);
    const uint64_t offsets_start = summary_start + summary.size();
    std::string offsets;
    for (const auto& [op, start, length] : groups) offsets += record(summary_offset, Out().u8(op).u64(start).u64(length).b);
    // The footer's CRC covers the summary, the offsets and the footer up to its own CRC field.
    Out footer_head;
    footer_head.u8(footer).u64(8 + 8 + 4).u64(summary_start).u64(offsets_start);
    const uint32_t summary_crc = crc_of(footer_head.b, crc_of(offsets, crc_of(summary)));
    put(summary);
    put(offsets);
    put(footer_head.b + Out().u32(summary_crc).b);
    put(std::string(kMagic, kMagicSize));
    if (reserved_end_ > offset_) (void)!::ftruncate(fd_, off_t(offset_));  // the room left over is freed
    const bool ok = ::fsync(fd_) == 0;
    ::close(fd_);
    fd_ = -1;
    if (!ok) throw cpm::Error("mcap: cannot finish " + path_ + ": " + std::strerror(errno));
}

// ---- read -----------------------------------------------------------------------------------------

namespace {

/// Reads fields from [at, end), naming the file and offset when one is cut short.
class In
{
public:
    In(const std::string& path, const std::string& bytes, size_t at, size_t end) : path_(path), b_(bytes), at_(at), end_(end)
    {
    }
    uint8_t u8() { return uint8_t(take(1)[0]); }
    uint16_t u16() { return uint16_t(le(2)); }
    uint32_t u32() { return uint32_t(le(4)); }
    uint64_t u64() { return le(8); }
    std::string str() { return take(u32()); }
    std::string bytes(size_t n) { return take(n); }
    std::map<std::string, std::string> string_map()
    {
        std::map<std::string, std::string> m;
        each_pair([&m](In& in) {
            std::string k = in.str();
            m[k] = in.str();
        });
        return m;
    }
    std::map<uint16_t, uint64_t> offsets_map()
    {
        std::map<uint16_t, uint64_t> m;
        each_pair([&m](In& in) {
            const uint16_t k = in.u16();
            m[k] = in.u64();
        });
        return m;
    }
    bool done() const { return at_ >= end_; }
    size_t at() const { return at_; }
    [[noreturn]] void fail(const std::string& what) const
    {
        throw cpm::Error("mcap: " + path_ + ": at byte " + std::to_string(at_) + ": " + what);
    }

private:
    /// A map's entries: its byte length, then `read_pair` until those bytes are read.
    template <class ReadPair>
    void each_pair(ReadPair read_pair)
    {
        const uint32_t n = u32();  // before at_ is read: the map begins after its length
        In inner(path_, b_, at_, at_ + n);
        if (inner.end_ > end_) fail("a map runs past its record");
        while (!inner.done()) read_pair(inner);
        at_ = inner.end_;
    }
    std::string take(size_t n)
    {
        if (n > end_ - at_) fail("cut short (" + std::to_string(n) + " bytes wanted, " + std::to_string(end_ - at_) + " left)");
        std::string s = b_.substr(at_, n);
        at_ += n;
        return s;
    }
    uint64_t le(int n)
    {
        const std::string s = take(size_t(n));
        uint64_t v = 0;
        for (int i = n - 1; i >= 0; --i) v = (v << 8) | uint8_t(s[size_t(i)]);
        return v;
    }
    const std::string& path_;
    const std::string& b_;
    size_t at_, end_;
};

/// The records of [at, end): a chunk's (in_chunk) or the file's data section.
void read_records(const std::string& path, const std::string& bytes, size_t at, size_t end, File& f, bool in_chunk)
{
    while (at < end) {
        In h(path, bytes, at, end);
        const uint8_t op = h.u8();
        const uint64_t len = h.u64();
        const size_t body = h.at();
        if (len > end - body) h.fail("a record (op " + std::to_string(op) + ") of " + std::to_string(len) + " bytes runs past its end");
        In r(path, bytes, body, body + len);
        switch (op) {
        case schema: {
            Schema s;
            s.id = r.u16();
            s.name = r.str();
            s.encoding = r.str();
            s.data = r.str();
            if (s.id == 0) r.fail("a Schema with id 0");
            f.schemas[s.id] = s;
            break;
        }
        case channel: {
            Channel c;
            c.id = r.u16();
            c.schema_id = r.u16();
            c.topic = r.str();
            c.message_encoding = r.str();
            c.metadata = r.string_map();
            f.channels[c.id] = c;
            break;
        }
        case message: {
            Message m;
            m.channel_id = r.u16();
            m.sequence = r.u32();
            m.log_time = r.u64();
            m.publish_time = r.u64();
            if (!f.channels.count(m.channel_id)) r.fail("a Message of channel " + std::to_string(m.channel_id) + " before that Channel");
            const std::string data = r.bytes(body + len - r.at());
            m.data.assign(data.begin(), data.end());
            f.messages.push_back(std::move(m));
            break;
        }
        case chunk: {
            if (in_chunk) r.fail("a Chunk inside a Chunk");
            (void)r.u64();
            (void)r.u64();
            const uint64_t uncompressed_size = r.u64();
            const uint32_t crc = r.u32();
            const std::string compression = r.str();
            if (!compression.empty()) r.fail("a chunk compressed with " + compression + " (cpm reads uncompressed chunks)");
            const uint64_t n = r.u64();
            const size_t start = r.at();
            const std::string records = r.bytes(n);
            if (n != uncompressed_size) r.fail("a chunk of " + std::to_string(n) + " bytes says it has " + std::to_string(uncompressed_size));
            if (crc != 0 && crc_of(records) != crc) r.fail("the chunk's CRC does not match its records");
            read_records(path, bytes, start, start + n, f, true);
            ++f.chunk_count;
            break;
        }
        case metadata: {
            Metadata m;
            m.name = r.str();
            m.values = r.string_map();
            f.metadata.push_back(std::move(m));
            break;
        }
        case message_index: ++f.message_indexes; break;
        default:
            if (op >= 0x80) f.privates.push_back({op, r.bytes(len), f.messages.size()});
            break;  // attachments and what a later version adds: skipped
        }
        at = body + len;
    }
}

}  // namespace

bool is_mcap(const std::string& path)
{
    std::ifstream in(path, std::ios::binary);
    char head[kMagicSize] = {};
    return in.read(head, kMagicSize) && std::memcmp(head, kMagic, kMagicSize) == 0;
}

File read(const std::string& path, Damage damage)
{
    std::ifstream in(path, std::ios::binary);
    if (!in) throw cpm::Error("mcap: cannot read " + path);
    const std::string b((std::istreambuf_iterator<char>(in)), {});
    const std::string magic(kMagic, kMagicSize);
    if (b.size() < kMagicSize || b.compare(0, kMagicSize, magic) != 0) In(path, b, 0, b.size()).fail("not an MCAP file (no magic)");
    const bool finished = b.size() >= 2 * kMagicSize && b.compare(b.size() - kMagicSize, kMagicSize, magic) == 0;
    File f;
    if (!finished) {
        if (damage == Damage::refuse) In(path, b, b.size(), b.size()).fail("no closing magic (the file was not finished)");
        f.damage = "it was not finished (no summary, no closing magic: its writer was stopped or killed)";
    }
    const size_t end = finished ? b.size() - kMagicSize : b.size();
    size_t at = kMagicSize;
    bool data_section = true;
    while (at < end) {
        // What a damaged record had added is taken back: a chunk reads whole or not at all.
        const size_t messages = f.messages.size(), privates = f.privates.size(), metadata = f.metadata.size();
        try {
            In h(path, b, at, end);
            const uint8_t op = h.u8();
            const uint64_t len = h.u64();
            const size_t body = h.at();
            if (len > end - body) h.fail("a record (op " + std::to_string(op) + ") of " + std::to_string(len) + " bytes runs past the file's end");
            In r(path, b, body, body + len);
            if (op == header) {
                f.profile = r.str();
                f.library = r.str();
            } else if (op == data_end) {
                const uint32_t crc = r.u32();
                if (crc != 0 && crc_of(b.substr(0, at)) != crc) r.fail("the data section's CRC does not match");
                data_section = false;
            } else if (op == footer) {
                f.summary_start = r.u64();
                (void)r.u64();
                const uint32_t crc = r.u32();
                if (f.summary_start > body + 16) r.fail("the footer's summary start lies past the footer");
            if (crc != 0 && f.summary_start != 0 && crc_of(b.substr(f.summary_start, body + 16 - f.summary_start)) != crc) {
                    r.fail("the summary's CRC does not match");
                }
            } else if (op == statistics) {
                f.statistics_messages = r.u64();
                (void)r.u16();
                for (int i = 0; i < 4; ++i) (void)r.u32();  // channel, attachment, metadata, chunk counts
                (void)r.u64();
                (void)r.u64();
                f.statistics_channel_counts = r.offsets_map();
            } else if (op == chunk_index) {
                ++f.chunk_indexes;
            } else if (data_section) {
                read_records(path, b, at, body + len, f, false);
            }  // the summary's copies of Schemas and Channels: the data section's are kept
            at = body + len;
        } catch (const cpm::Error& e) {
            if (damage == Damage::refuse) throw;
            f.messages.resize(messages);
            f.privates.resize(privates);
            f.metadata.resize(metadata);
            const std::string why = e.what();
            // Named by where its record starts: the file's whole records end there.
            const size_t what = why.find(": ", why.find(": at byte ") + 2);
            f.damage = (finished ? "" : f.damage + "; ") + "at byte " + std::to_string(at) + why.substr(what) + " (" +
                       std::to_string(b.size() - at) + " bytes from there on are not read)";
            break;
        }
    }
    return f;
}

}  // namespace cpm::rtdb::mcap
