#include "RecordingFile.hpp"

#include <cpm/rtdb/IdlDecoder.hpp>
#include <cpm/rtdb/Mcap.hpp>
#include <cpm/topics.hpp>

#include "Sqlite.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>
#include <cstring>
#include <filesystem>
#include <regex>
#include <set>
#include <sstream>

namespace cpm::rtdb {

namespace {

using sqlite::Statement;
using sqlite::exec;
using sqlite::sqlite_error;


const char* const kTables =
    "CREATE TABLE meta(key TEXT PRIMARY KEY, value TEXT NOT NULL);"
    "CREATE TABLE types(file TEXT PRIMARY KEY, idl TEXT NOT NULL);"
    "CREATE TABLE objects(oid INTEGER PRIMARY KEY, kind TEXT NOT NULL, name TEXT NOT NULL, topic TEXT NOT NULL,"
    " key TEXT NOT NULL, type_name TEXT NOT NULL, parent INTEGER NOT NULL, creator TEXT NOT NULL,"
    " creator_guid TEXT NOT NULL, created_ns INTEGER NOT NULL, deleted_ns INTEGER NOT NULL,"
    " history_interval_ns INTEGER NOT NULL, data_time TEXT NOT NULL);"
    "CREATE TABLE samples(oid INTEGER NOT NULL, commit_ns INTEGER NOT NULL, data_ns INTEGER NOT NULL,"
    " valid_after_ns INTEGER NOT NULL, source_ns INTEGER NOT NULL, lost_before INTEGER NOT NULL, payload BLOB NOT NULL);";

/// The meta a file begins with: the format, its version, then what the recorder says.
std::map<std::string, std::string> with_format(std::map<std::string, std::string> meta)
{
    meta["format"] = kRecordingFormat;
    meta["version"] = kRecordingVersion;
    return meta;
}

// ---- SQLite ---------------------------------------------------------------------------------

class SqliteFile final : public RecordingFile
{
public:
    SqliteFile(sqlite3* db, bool owned, const std::map<std::string, std::string>& meta, const std::map<std::string, std::string>& idl)
        : db_(db), owned_(owned)
    {
        check(exec(db_, std::string("BEGIN;") + kTables), "cannot make its tables");
        Statement m(db_, "INSERT INTO meta VALUES(?, ?)");
        for (const auto& [k, v] : with_format(meta)) check(m.bind(1, k).bind(2, v).run(), "cannot write its meta table");
        Statement t(db_, "INSERT INTO types VALUES(?, ?)");
        for (const auto& [file, text] : idl) check(t.bind(1, file).bind(2, text).run(), "cannot write the IDL");
        check(exec(db_, "COMMIT;"), "cannot write it");
        add_ = std::make_unique<Statement>(db_, "INSERT OR REPLACE INTO objects VALUES(?,?,?,?,?,?,?,?,?,?,?,?,?)");
        sample_ = std::make_unique<Statement>(db_, "INSERT INTO samples VALUES(?,?,?,?,?,?,?)");
        del_ = std::make_unique<Statement>(db_, "UPDATE objects SET deleted_ns = ? WHERE oid = ?");
    }
    ~SqliteFile() override
    {
        add_.reset();
        sample_.reset();
        del_.reset();
        if (owned_) sqlite3_close(db_);
    }

    void add_object(const ObjectInfo& i) override
    {
        begin();
        check(add_->bind(1, i.oid)
                  .bind(2, std::string(i.kind == ObjectKind::process ? "process" : "instance"))
                  .bind(3, i.name)
                  .bind(4, i.topic)
                  .bind(5, i.key)
                  .bind(6, i.type_name)
                  .bind(7, i.parent)
                  .bind(8, i.creator)
                  .bind(9, i.creator_guid)
                  .bind(10, i.created_ts)
                  .bind(11, i.deleted_ts)
                  .bind(12, i.history_interval_ns)
                  .bind(13, i.data_time)
                  .run(),
              "cannot write to it");
    }
    void add_sample(Oid oid, const RecordedSample& s) override
    {
        begin();
        check(sample_->bind(1, oid)
                  .bind(2, s.commit_ns)
                  .bind(3, s.data_ns)
                  .bind(4, s.valid_after_ns)
                  .bind(5, s.source_ns)
                  .bind(6, s.lost_before)
                  .bind_blob(7, s.payload, s.size)
                  .run(),
              "cannot write to it");
        ++pending_;
    }
    void delete_object(Oid oid, uint64_t deleted_ns) override
    {
        begin();
        check(del_->bind(1, deleted_ns).bind(2, oid).run(), "cannot write to it");
    }
    void commit() override
    {
        if (!open_) return;
        open_ = false;
        check(exec(db_, "COMMIT"), "cannot write to it");
        committed_ += pending_;
        pending_ = 0;
    }
    uint64_t samples_in_file() const override { return committed_; }
    uint64_t bytes() const override
    {
        Statement pages(db_, "SELECT page_count * page_size FROM pragma_page_count(), pragma_page_size()");
        return pages.step() == SQLITE_ROW ? pages.u64(0) : 0;
    }
    void finish(const std::map<std::string, std::string>& end) override
    {
        if (open_) exec(db_, "ROLLBACK");
        open_ = false;
        // The end, an index for people who open the file with sqlite3, and one file again (no
        // WAL). After a failure these may fail too: what was committed is kept either way.
        try {
            Statement m(db_, "INSERT OR REPLACE INTO meta VALUES(?, ?)");
            for (const auto& [k, v] : end) (void)m.bind(1, k).bind(2, v).run();
        } catch (const std::runtime_error&) {
        }
        exec(db_, "CREATE INDEX IF NOT EXISTS samples_by_object ON samples(oid, commit_ns)");
        if (owned_) exec(db_, "PRAGMA wal_checkpoint(TRUNCATE); PRAGMA journal_mode=DELETE;");
    }

private:
    void begin()
    {
        if (open_) return;
        check(exec(db_, "BEGIN"), "cannot write to it");
        open_ = true;
    }
    void check(int rc, const char* what)
    {
        if (rc == SQLITE_OK) return;
        const std::string why = sqlite_error(db_, rc);
        if (!sqlite3_get_autocommit(db_)) exec(db_, "ROLLBACK");  // a failed COMMIT may leave it open
        open_ = false;
        pending_ = 0;
        if (rc == SQLITE_FULL) throw RecordingFull("the disk is full (or the recording reached its size limit): " + why);
        throw Error(std::string(what) + ": " + why);
    }

    sqlite3* db_;
    bool owned_;
    bool open_ = false;  // a transaction
    uint64_t pending_ = 0, committed_ = 0;  // samples
    std::unique_ptr<Statement> add_, sample_, del_;
};

std::unique_ptr<RecordingFile> create_sqlite(const std::string& path, const std::map<std::string, std::string>& meta,
                                             const std::map<std::string, std::string>& idl, uint64_t max_bytes)
{
    sqlite3* db = nullptr;
    int rc = sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_NOMUTEX, nullptr);
    auto give_up = [&](const std::string& what) {
        const std::string e = "recording " + path + ": " + what + ": " + sqlite_error(db, rc);
        sqlite3_close(db);
        ::unlink(path.c_str());
        throw Error(e);
    };
    if (rc != SQLITE_OK) give_up("cannot create it");
    if ((rc = exec(db, "PRAGMA journal_mode=WAL; PRAGMA synchronous=NORMAL;")) != SQLITE_OK) give_up("cannot set WAL mode");
    if (max_bytes) {
        Statement size(db, "PRAGMA page_size");
        const uint64_t page = size.step() == SQLITE_ROW ? std::max<uint64_t>(size.u64(0), 512) : 4096;
        exec(db, "PRAGMA max_page_count=" + std::to_string(std::max<uint64_t>(max_bytes / page, 16)) + ";");
    }
    try {
        return std::make_unique<SqliteFile>(db, true, meta, idl);
    } catch (const std::runtime_error& e) {
        sqlite3_close(db);
        ::unlink(path.c_str());
        throw Error("recording " + path + ": " + e.what());
    }
}

// ---- MCAP -----------------------------------------------------------------------------------

enum : uint8_t { op_object = 0x80, op_sample = 0x81, op_deleted = 0x82 };

void put_u64(std::string& b, uint64_t v)
{
    for (int i = 0; i < 8; ++i) b.push_back(char((v >> (8 * i)) & 0xFF));
}

uint64_t get_u64(const std::string& b, size_t at)
{
    uint64_t v = 0;
    for (int i = 7; i >= 0; --i) v = (v << 8) | uint8_t(b[at + size_t(i)]);
    return v;
}

nlohmann::json object_json(const ObjectInfo& i)
{
    return {{"oid", i.oid},
            {"kind", i.kind == ObjectKind::process ? "process" : "instance"},
            {"name", i.name},
            {"topic", i.topic},
            {"key", i.key},
            {"type_name", i.type_name},
            {"parent", i.parent},
            {"creator", i.creator},
            {"creator_guid", i.creator_guid},
            {"created_ns", i.created_ts},
            {"deleted_ns", i.deleted_ts},
            {"history_interval_ns", i.history_interval_ns},
            {"data_time", i.data_time}};
}

ObjectInfo object_of(const nlohmann::json& j)
{
    ObjectInfo i;
    i.oid = j.at("oid").get<Oid>();
    i.kind = j.at("kind") == "process" ? ObjectKind::process : ObjectKind::instance;
    i.name = j.at("name").get<std::string>();
    i.topic = j.at("topic").get<std::string>();
    i.key = j.at("key").get<std::string>();
    i.type_name = j.at("type_name").get<std::string>();
    i.parent = j.at("parent").get<Oid>();
    i.creator = j.at("creator").get<std::string>();
    i.creator_guid = j.at("creator_guid").get<std::string>();
    i.created_ts = j.at("created_ns").get<uint64_t>();
    i.deleted_ts = j.at("deleted_ns").get<uint64_t>();
    i.history_interval_ns = j.at("history_interval_ns").get<uint64_t>();
    i.data_time = j.at("data_time").get<std::string>();
    return i;
}

/// Foxglove's FrameTransform (foxglove/schemas, OMG IDL), which its 3D panel places frames by.
constexpr const char* kFrameTransformIdl = R"(module foxglove {
struct Time { uint32 sec; uint32 nsec; };
struct Vector3 { double x; double y; double z; };
struct Quaternion { double x; double y; double z; double w; };
struct FrameTransform {
  Time timestamp;
  string parent_frame_id;
  string child_frame_id;
  Vector3 translation;
  Quaternion rotation;
};
};
)";

/// A FrameTransform in plain little-endian CDR (its encapsulation header first): frame `child`
/// in "map" at (x, y) turned by yaw about z, at time `t_ns`.
std::string frame_transform(uint64_t t_ns, const std::string& child, double x, double y, double yaw)
{
    std::string b{0, 1, 0, 0};  // CDR, little endian
    auto align = [&](size_t n) {
        while ((b.size() - 4) % n) b.push_back(0);
    };
    auto u32 = [&](uint32_t v) {
        align(4);
        for (int i = 0; i < 4; ++i) b.push_back(char((v >> (8 * i)) & 0xFF));
    };
    auto text = [&](const std::string& s) {
        u32(uint32_t(s.size() + 1));
        b += s;
        b.push_back(0);
    };
    auto f64 = [&](double v) {
        align(8);
        uint64_t bits;
        std::memcpy(&bits, &v, 8);
        for (int i = 0; i < 8; ++i) b.push_back(char((bits >> (8 * i)) & 0xFF));
    };
    u32(uint32_t(t_ns / 1'000'000'000ull));
    u32(uint32_t(t_ns % 1'000'000'000ull));
    text("map");
    text(child);
    for (double v : {x, y, 0.0, 0.0, 0.0, std::sin(yaw / 2), std::cos(yaw / 2)}) f64(v);
    return b;
}

/// The QoS cpm's writers offer on a topic of the lab's table, as JSON ("" for another topic).
std::string qos_of(const std::string& topic)
{
    const TopicSpec* t = topics::find(topic);
    if (!t) return "";
    const WriterOptions& w = t->writer;
    return nlohmann::json{{"reliable", w.reliable}, {"transient_local", w.transient_local}, {"keep_all", w.keep_all}, {"history_depth", w.history_depth}}
        .dump();
}

class McapFile final : public RecordingFile
{
public:
    McapFile(const std::string& path, const std::map<std::string, std::string>& meta, const std::map<std::string, std::string>& idl,
             uint64_t max_bytes, bool foxglove_3d)
        : writer_(path, std::string("cpm ") + CPM_VERSION, chunk_size(max_bytes), max_bytes), idl_(idl), foxglove_3d_(foxglove_3d),
          last_flush_(std::chrono::steady_clock::now())
    {
        guarded([&] {
            writer_.add_metadata("cpm.recording", with_format(meta));
            if (!idl.empty()) writer_.add_metadata("cpm.idl", idl);
        });
    }

    void add_object(const ObjectInfo& i) override
    {
        objects_[i.oid] = {i.topic, i.type_name, i.data_time == "create_stamp"};
        guarded([&] { writer_.write_private(op_object, object_json(i).dump()); });
    }
    void add_sample(Oid oid, const RecordedSample& s) override
    {
        const auto o = objects_.find(oid);
        if (o == objects_.end()) throw Error("a sample of object " + std::to_string(oid) + " before its info block");
        const uint16_t channel = channel_of(o->second);
        std::string extra;
        put_u64(extra, oid);
        put_u64(extra, s.valid_after_ns);
        put_u64(extra, s.source_ns);
        put_u64(extra, s.lost_before);
        put_u64(extra, s.data_ns);  // publish_time holds it only for a stamped type
        uint32_t& sequence = sequences_[channel];
        sequence += uint32_t(s.lost_before);  // a gap: the samples its writers sent that never came
        guarded([&] {
            writer_.write_private(op_sample, extra);
            writer_.write(channel, s.commit_ns, o->second.stamped ? s.data_ns : s.commit_ns, s.payload, s.size, sequence++);
        });
        if (foxglove_3d_) frames(o->second, s);
        // A bookmark is also the file's metadata, which viewers list.
        if (o->second.topic == topics::bookmark.name && decoder()) {
            if (const auto b = decoder()->decode(o->second.type_name, s.payload, s.size)) {
                guarded([&] {
                    writer_.add_metadata("cpm.bookmark", {{"time_ns", std::to_string(s.data_ns)},
                                                          {"text", b->value("text", "")},
                                                          {"source", b->value("source", "")}});
                });
            }
        }
    }
    void delete_object(Oid oid, uint64_t deleted_ns) override
    {
        std::string body;
        put_u64(body, oid);
        put_u64(body, deleted_ns);
        guarded([&] { writer_.write_private(op_deleted, body); });
    }
    void add_metadata(const std::string& name, const std::map<std::string, std::string>& values) override
    {
        guarded([&] { writer_.add_metadata(name, values); });
    }
    void commit() override
    {
        if (std::chrono::steady_clock::now() - last_flush_ < std::chrono::seconds(1)) return;
        last_flush_ = std::chrono::steady_clock::now();
        guarded([&] { writer_.flush(); });
    }
    void finish(const std::map<std::string, std::string>& end) override
    {
        try {
            if (!end.empty()) writer_.add_metadata("cpm.recording_end", end);
        } catch (const Error&) {
            // The last chunk did not fit: the file is closed without it.
        }
        writer_.close();
    }

    /// The run's samples: the messages but those derived for viewers (/tf).
    uint64_t samples_in_file() const override { return writer_.messages() - (tf_channel_ ? writer_.channel_messages(*tf_channel_) : 0); }
    uint64_t bytes() const override { return writer_.bytes(); }

private:
    struct Topic
    {
        std::string topic, type_name;
        bool stamped = true;
    };
    /// A car's pose also as a FrameTransform on /tf, for Foxglove's 3D panel: car_<id> from
    /// vehicleObservation (its true pose), car_<id>_estimate from vehicleState (its own).
    void frames(const Topic& t, const RecordedSample& s)
    {
        const bool truth = t.topic == topics::vehicle_observation.name;
        if ((!truth && t.topic != topics::vehicle_state.name) || !decoder()) return;
        const auto j = decoder()->decode(t.type_name, s.payload, s.size);
        if (!j || !j->contains("pose")) return;
        const auto& pose = (*j)["pose"];
        if (!tf_channel_) tf_channel_ = writer_.add_channel(writer_.add_schema("foxglove::FrameTransform", "omgidl", kFrameTransformIdl), "/tf", "cdr",
                                                            {{"cpm.derived", "the cars' poses for Foxglove's 3D panel"}});
        const std::string frame = "car_" + std::to_string(j->value("vehicle_id", 0)) + (truth ? "" : "_estimate");
        const std::string b = frame_transform(s.data_ns, frame, pose.value("x", 0.0), pose.value("y", 0.0), pose.value("yaw", 0.0));
        guarded([&] { writer_.write(*tf_channel_, s.commit_ns, s.data_ns, reinterpret_cast<const uint8_t*>(b.data()), b.size()); });
    }

    /// 256 KiB: what a recorder killed loses at most (or a second's worth); smaller under a
    /// size limit, so that a limit ends the file after many chunks, not before the first.
    static size_t chunk_size(uint64_t max_bytes)
    {
        return max_bytes ? size_t(std::clamp<uint64_t>(max_bytes / 16, 4096, 256 * 1024)) : 256 * 1024;
    }
    template <class Write>
    void guarded(Write write)
    {
        try {
            write();
        } catch (const Error& e) {
            const std::string why = e.what();
            if (why.find("size limit") != std::string::npos || why.find(std::strerror(ENOSPC)) != std::string::npos) {
                throw RecordingFull("the disk is full (or the recording reached its size limit): " + why);
            }
            throw;
        }
    }
    uint16_t channel_of(const Topic& t)
    {
        auto c = channels_.find(t.topic);
        if (c != channels_.end()) return c->second;
        auto s = schemas_.find(t.type_name);
        if (s == schemas_.end()) {
            const std::string text = self_contained_idl(idl_, t.type_name);
            // A type the recording has no IDL for: its channel has no schema (schema id 0).
            s = schemas_.emplace(t.type_name, text.empty() ? 0 : writer_.add_schema(t.type_name, "omgidl", text)).first;
        }
        std::map<std::string, std::string> meta{{"cpm.type", t.type_name}};
        const IdlDecoder* types = decoder();
        meta["cpm.keyed"] = types && !types->key_members(t.type_name).empty() ? "true" : "false";
        if (const std::string qos = qos_of(t.topic); !qos.empty()) meta["cpm.qos"] = qos;
        return channels_[t.topic] = writer_.add_channel(s->second, t.topic, "cdr", meta);
    }
    const IdlDecoder* decoder()
    {
        if (!decoder_ && !idl_.empty()) {
            try {
                decoder_ = std::make_unique<IdlDecoder>(idl_);
            } catch (const std::exception&) {
            }
        }
        return decoder_.get();
    }

    mcap::Writer writer_;
    std::map<std::string, std::string> idl_;
    std::unique_ptr<IdlDecoder> decoder_;
    std::map<Oid, Topic> objects_;
    std::map<std::string, uint16_t> schemas_, channels_;
    std::map<uint16_t, uint32_t> sequences_;
    bool foxglove_3d_;
    std::optional<uint16_t> tf_channel_;
    std::chrono::steady_clock::time_point last_flush_;
};

// ---- MCAP into the recording's tables --------------------------------------------------------

/// Objects for a file cpm did not write: one per channel and key (the key read with the
/// channel's IDL where it has one).
class ForeignObjects
{
public:
    ForeignObjects(const mcap::File& f, const IdlDecoder* types) : f_(f), types_(types) {}
    Oid oid_of(const mcap::Message& m, RecordingFile& out)
    {
        const mcap::Channel& c = f_.channels.at(m.channel_id);
        const auto s = f_.schemas.find(c.schema_id);
        const std::string type = s == f_.schemas.end() ? c.topic : s->second.name;
        std::string key;
        if (types_ && types_->knows(type)) key = types_->key_text(type, m.data.data(), m.data.size()).value_or("");
        auto [it, added] = oids_.emplace(std::make_pair(c.id, key), Oid(oids_.size() + 1));
        if (added) {
            ObjectInfo i;
            i.oid = it->second;
            i.topic = c.topic;
            i.key = key;
            i.name = key.empty() ? c.topic : c.topic + "/" + key;
            i.type_name = type;
            i.created_ts = m.log_time;
            i.data_time = types_ && types_->knows(type) && types_->has_header(type) ? "create_stamp" : "source_timestamp";
            out.add_object(i);
        }
        return it->second;
    }

private:
    const mcap::File& f_;
    const IdlDecoder* types_;
    std::map<std::pair<uint16_t, std::string>, Oid> oids_;
};

}  // namespace

RecordingFormat recording_format(const std::string& path, const std::string& format)
{
    if (format == "mcap") return RecordingFormat::mcap;
    if (format == "sqlite") return RecordingFormat::sqlite;
    if (!format.empty()) throw Error("recording format '" + format + "': expected sqlite or mcap");
    return std::filesystem::path(path).extension() == ".mcap" ? RecordingFormat::mcap : RecordingFormat::sqlite;
}

std::unique_ptr<RecordingFile> create_recording_file(const std::string& path, RecordingFormat format,
                                                     const std::map<std::string, std::string>& meta,
                                                     const std::map<std::string, std::string>& idl, uint64_t max_bytes, bool foxglove_3d)
{
    if (sqlite::file_exists(path)) throw Error("recording " + path + ": the file exists already (a recording is never overwritten)");
    if (format == RecordingFormat::sqlite) return create_sqlite(path, meta, idl, max_bytes);
    try {
        return std::make_unique<McapFile>(path, meta, idl, max_bytes, foxglove_3d);
    } catch (const Error& e) {
        throw Error("recording " + path + ": " + e.what());
    }
}

std::unique_ptr<RecordingFile> recording_tables_in(sqlite3* db, const std::map<std::string, std::string>& meta,
                                                   const std::map<std::string, std::string>& idl)
{
    return std::make_unique<SqliteFile>(db, false, meta, idl);
}

void copy_mcap_into(const std::string& path, sqlite3* db)
{
    const mcap::File f = mcap::read(path, mcap::Damage::keep_what_reads);
    if (!f.damage.empty() && f.messages.empty() && f.metadata.empty() && f.channels.empty()) {
        throw Error("recording " + path + ": nothing of it reads: " + f.damage);
    }
    std::map<std::string, std::string> meta, idl, end;
    for (const auto& m : f.metadata) {
        if (m.name == "cpm.recording") meta = m.values;
        if (m.name == "cpm.idl") idl = m.values;
        if (m.name == "cpm.recording_end") end = m.values;
    }
    const bool ours = !meta.empty();
    if (ours && meta["version"] != kRecordingVersion) {
        throw Error("recording " + path + ": recording format version " + meta["version"] + ", this cpm reads version " + kRecordingVersion);
    }
    if (!ours) {  // another tool's file: its name, its start, the IDL of its schemas
        meta = {{"name", std::filesystem::path(path).stem().string()}, {"host", ""}};
        meta["started_ns"] = std::to_string(f.messages.empty() ? 0 : f.messages.front().log_time);
        for (const auto& [id, s] : f.schemas) {
            if (s.encoding == "omgidl") idl[s.name + ".idl"] = s.data;
        }
        if (f.summary_start != 0) end["ended_ns"] = std::to_string(f.messages.empty() ? 0 : f.messages.back().log_time);
    }
    std::unique_ptr<IdlDecoder> types;
    try {
        if (!idl.empty()) types = std::make_unique<IdlDecoder>(idl);
    } catch (const std::exception&) {
    }
    auto out = recording_tables_in(db, meta, idl);
    ForeignObjects foreign(f, types.get());
    size_t p = 0;
    std::optional<std::string> sample;  // the cpm.sample record of the next message
    for (size_t i = 0; i <= f.messages.size(); ++i) {
        for (; p < f.privates.size() && f.privates[p].before_message == i; ++p) {
            const mcap::Private& r = f.privates[p];
            if (r.op == op_object) {
                try {
                    out->add_object(object_of(nlohmann::json::parse(r.body)));
                } catch (const nlohmann::json::exception& e) {
                    throw Error("recording " + path + ": an object record does not read: " + e.what());
                }
            } else if (r.op == op_sample && r.body.size() == 40) {
                sample = r.body;
            } else if (r.op == op_deleted && r.body.size() == 16) {
                out->delete_object(get_u64(r.body, 0), get_u64(r.body, 8));
            }
        }
        if (i == f.messages.size()) break;
        const mcap::Message& m = f.messages[i];
        RecordedSample s{.commit_ns = m.log_time, .data_ns = m.publish_time, .valid_after_ns = m.publish_time, .payload = m.data.data(),
                         .size = m.data.size()};
        if (ours && !sample) continue;  // derived for viewers (Foxglove's /tf): no sample of the run
        Oid oid;
        if (ours && sample) {
            oid = get_u64(*sample, 0);
            s.valid_after_ns = get_u64(*sample, 8);
            s.source_ns = get_u64(*sample, 16);
            s.lost_before = get_u64(*sample, 24);
            s.data_ns = get_u64(*sample, 32);
        } else {
            oid = foreign.oid_of(m, *out);
            s.source_ns = m.publish_time;
        }
        sample.reset();
        out->add_sample(oid, s);
    }
    out->commit();
    // Not finished is said by the missing end; other damage by name.
    if (const size_t at = f.damage.find("at byte "); at != std::string::npos) end["damage"] = "it is damaged " + f.damage.substr(at);
    out->finish(end);
}

std::string self_contained_idl(const std::map<std::string, std::string>& sources, const std::string& type_name)
{
    const std::regex defines("\\b(struct|union|enum)\\s+" + type_name + "\\s*\\{");
    const auto home = std::find_if(sources.begin(), sources.end(), [&](const auto& f) { return std::regex_search(f.second, defines); });
    if (home == sources.end()) return "";
    std::string out;
    std::set<std::string> done;
    const std::regex include("^\\s*#\\s*include\\s*[\"<]([^\">]+)[\">]");
    std::function<void(const std::string&)> add = [&](const std::string& file) {
        if (!done.insert(file).second) return;
        const auto f = sources.find(std::filesystem::path(file).filename().string());
        if (f == sources.end()) return;
        std::istringstream lines(f->second);
        std::string own;
        for (std::string line; std::getline(lines, line);) {
            std::smatch m;
            if (std::regex_search(line, m, include)) add(m[1].str());
            else if (line.find_first_not_of(" \t") == std::string::npos || line[line.find_first_not_of(" \t")] != '#') own += line + "\n";
        }
        out += own;
    };
    add(home->first);
    return out;
}

}  // namespace cpm::rtdb
