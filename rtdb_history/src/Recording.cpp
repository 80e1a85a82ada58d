#include <cpm/rtdb/Recording.hpp>

#include <cpm/Logging.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/rtdb/IdlDecoder.hpp>
#include <cpm/rtdb/Requests.hpp>
#include <cpm/topics.hpp>
#include <cpm/Error.hpp>
#include <cpm/CommandLine.hpp>
#include <cpm/HistoryClient.hpp>

#include "RecordingFile.hpp"
#include "Sqlite.hpp"

#include <cpm/rtdb/Mcap.hpp>

#include <cctype>
#include <filesystem>
#include <limits>
#include <mutex>
#include <regex>
#include <set>
#include <sstream>
#include <stdexcept>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <unistd.h>
#include <variant>

namespace cpm::rtdb {

namespace {

using sqlite::Statement;
using sqlite::exec;
using sqlite::file_exists;
using sqlite::sqlite_error;


/// An MCAP file as a recording's tables in an SQLite database in memory, made once per file
/// (and again when the file changed) and kept for the process's life; its URI.
std::string mcap_as_tables(const std::string& path)
{
    struct Copy
    {
        std::string uri;
        sqlite3* keeper = nullptr;  // the memory database lives while a connection is open
        std::filesystem::file_time_type written;
        uintmax_t size = 0;
    };
    static std::mutex mutex;
    static std::map<std::string, Copy> copies;
    static int made = 0;
    std::lock_guard lock(mutex);
    const std::string key = std::filesystem::absolute(path).lexically_normal().string();
    std::error_code ec;
    const auto written = std::filesystem::last_write_time(path, ec);
    const auto size = std::filesystem::file_size(path, ec);
    auto it = copies.find(key);
    if (it != copies.end() && it->second.written == written && it->second.size == size) return it->second.uri;
    Copy c{"file:cpm_mcap_" + std::to_string(::getpid()) + "_" + std::to_string(++made) + "?mode=memory&cache=shared", nullptr, written, size};
    if (sqlite3_open_v2(c.uri.c_str(), &c.keeper, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_URI, nullptr) != SQLITE_OK) {
        const std::string why = sqlite_error(c.keeper, SQLITE_ERROR);
        sqlite3_close(c.keeper);
        throw Error("recording " + path + ": cannot make a database in memory to read it into: " + why);
    }
    try {
        copy_mcap_into(path, c.keeper);
    } catch (const std::exception& e) {
        sqlite3_close(c.keeper);
        const std::string why = e.what();
        throw Error(why.rfind("recording ", 0) == 0 ? why : "recording " + path + ": " + why);
    }
    if (it != copies.end()) sqlite3_close(it->second.keeper);
    copies[key] = c;
    return c.uri;
}

}  // namespace

std::vector<std::string> recording_files(const std::string& path)
{
    namespace fs = std::filesystem;
    std::vector<std::string> files;
    if (path.find('\n') != std::string::npos) {  // several --file: one recording, in the order given
        std::istringstream list(path);
        for (std::string f; std::getline(list, f);) {
            const auto one = recording_files(f);
            if (one.size() != 1) throw Error("recording " + f + ": a folder in a list of files; give its files");
            files.push_back(one[0]);
        }
        return files;
    }
    if (!file_exists(path)) throw Error("recording " + path + ": no such file");
    std::error_code ec;
    if (!fs::is_directory(path, ec)) return {path};
    // A folder: its run's recording (a run's folder also holds its saves), else its split
    // recording (<stem>_NNN.db|.mcap, one set).
    for (const char* run : {"recording.db", "recording.mcap"}) {
        if (fs::is_regular_file(fs::path(path) / run, ec)) return {(fs::path(path) / run).string()};
    }
    static const std::regex part(R"((.*)_(\d{3,})\.(db|mcap))");
    std::map<std::string, std::vector<std::pair<uint64_t, std::string>>> sets;
    for (const auto& e : fs::directory_iterator(path, ec)) {
        std::smatch m;
        const std::string name = e.path().filename().string();
        if (e.is_regular_file() && std::regex_match(name, m, part)) sets[m[1].str() + "." + m[3].str()].emplace_back(std::stoull(m[2].str()), e.path().string());
    }
    if (sets.size() == 1) {
        auto parts = sets.begin()->second;
        std::sort(parts.begin(), parts.end());  // by number: _1000 after _999
        for (const auto& [n, f] : parts) files.push_back(f);
        return files;
    }
    if (sets.size() > 1) {
        std::string names;
        for (const auto& [stem, parts] : sets) names += (names.empty() ? "" : ", ") + stem + " (" + std::to_string(parts.size()) + " files)";
        throw Error("recording " + path + ": it is a directory with several split recordings (" + names + "); give one's files with --file each");
    }
    throw Error("recording " + path + ": it is a directory without a recording (no recording.db, recording.mcap or split recording NAME_000.db|.mcap in it)");
}

namespace {

/// Several files of one recording (a split one, or several named) as one recording's tables in
/// an SQLite database in memory, made once per set; its URI. The objects' info blocks are the
/// newest file's, the samples each file's in order, without those a file carries at its start
/// from the one before (the first file's are kept: the state at its start).
std::string set_as_tables(const std::string& key, const std::vector<std::string>& files)
{
    static std::mutex mutex;
    static std::map<std::string, std::pair<std::string, sqlite3*>> made;
    static int count = 0;
    std::lock_guard lock(mutex);
    if (auto it = made.find(key); it != made.end()) return it->second.first;
    const std::string uri = "file:cpm_set_" + std::to_string(::getpid()) + "_" + std::to_string(++count) + "?mode=memory&cache=shared";
    sqlite3* keeper = nullptr;
    if (sqlite3_open_v2(uri.c_str(), &keeper, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_URI, nullptr) != SQLITE_OK) {
        sqlite3_close(keeper);
        throw Error("recording " + files.front() + ": cannot make a database in memory to read its files into");
    }
    try {
        std::map<std::string, std::string> first_meta, last_meta;
        uint64_t samples = 0, dropped = 0;
        for (size_t i = 0; i < files.size(); ++i) {
            std::map<std::string, std::string> meta;
            std::unique_ptr<sqlite3, int (*)(sqlite3*)> part(open_recording_file(files[i], meta), sqlite3_close);
            if (i == 0) {
                first_meta = meta;
                std::map<std::string, std::string> idl;
                Statement t(part.get(), "SELECT file, idl FROM types");
                while (t.step() == SQLITE_ROW) idl[t.text(0)] = t.text(1);
                std::map<std::string, std::string> begin;
                for (const char* k : {"name", "host", "started_ns"}) begin[k] = meta[k];
                (void)recording_tables_in(keeper, begin, idl);
            } else if (meta["started_ns"] != first_meta["started_ns"] || meta["name"] != first_meta["name"]) {
                throw Error(files[i] + " is of another recording than " + files.front() + " (its start or name differs)");
            }
            last_meta = meta;
            samples += std::strtoull(meta["samples"].c_str(), nullptr, 10);
            dropped += std::strtoull(meta["dropped"].c_str(), nullptr, 10);
            const std::string source = mcap::is_mcap(files[i]) ? mcap_as_tables(files[i]) : files[i];
            Statement attach(keeper, "ATTACH DATABASE ? AS part");
            if (attach.bind(1, source).run() != SQLITE_OK) throw Error("cannot read " + files[i] + ": " + sqlite3_errmsg(keeper));
            const uint64_t carried = i == 0 ? 0 : std::strtoull(meta["carried_samples"].c_str(), nullptr, 10);
            const std::string sql = "INSERT OR REPLACE INTO main.objects SELECT * FROM part.objects;"
                                    "INSERT INTO main.samples SELECT * FROM part.samples WHERE rowid NOT IN"
                                    " (SELECT rowid FROM part.samples ORDER BY rowid LIMIT " + std::to_string(carried) + ") ORDER BY rowid;";
            const int rc = exec(keeper, sql);
            exec(keeper, "DETACH DATABASE part");
            if (rc != SQLITE_OK) throw Error("cannot read " + files[i] + ": " + sqlite_error(keeper, rc));
        }
        std::map<std::string, std::string> end{{"parts", std::to_string(files.size())}};
        if (last_meta.count("ended_ns")) {
            end["ended_ns"] = last_meta["ended_ns"];
            end["samples"] = std::to_string(samples);
            end["dropped"] = std::to_string(dropped);
        }
        Statement m(keeper, "INSERT OR REPLACE INTO meta VALUES(?, ?)");
        for (const auto& [k, v] : end) (void)m.bind(1, k).bind(2, v).run();
        exec(keeper, "CREATE INDEX IF NOT EXISTS samples_by_object ON samples(oid, commit_ns)");
    } catch (const std::exception& e) {
        sqlite3_close(keeper);
        const std::string why = e.what();
        throw Error(why.rfind("recording ", 0) == 0 ? why : "recording " + files.front() + ": " + why);
    }
    made[key] = {uri, keeper};
    return uri;
}

}  // namespace

sqlite3* open_recording_file(const std::string& path, std::map<std::string, std::string>& meta)
{
    const std::vector<std::string> files = recording_files(path);
    sqlite3* db = nullptr;
    int rc = SQLITE_OK;
    if (files.size() > 1) {
        std::string key = path;  // a file that changed since is read again
        for (const auto& f : files) {
            std::error_code ec;
            key += "|" + std::to_string(std::filesystem::file_size(f, ec)) + "@" +
                   std::to_string(std::filesystem::last_write_time(f, ec).time_since_epoch().count());
        }
        rc = sqlite3_open_v2(set_as_tables(key, files).c_str(), &db, SQLITE_OPEN_READWRITE | SQLITE_OPEN_URI, nullptr);
    } else if (const std::string& file = files.front(); file != path) {
        return open_recording_file(file, meta);  // a run's folder: its recording
    } else if (mcap::is_mcap(path)) {
        rc = sqlite3_open_v2(mcap_as_tables(path).c_str(), &db, SQLITE_OPEN_READWRITE | SQLITE_OPEN_URI, nullptr);
    } else {
        // Read-write when it may (a recording left with its WAL beside it is then read whole),
        // else read-only; nothing is changed either way.
        rc = sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READWRITE, nullptr);
        if (rc != SQLITE_OK) {
            sqlite3_close(db);
            rc = sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr);
        }
    }
    std::unique_ptr<sqlite3, int (*)(sqlite3*)> owner(db, sqlite3_close);
    auto fail = [&](const std::string& what) { return Error("recording " + path + ": " + what); };
    if (rc != SQLITE_OK) throw fail("cannot open it: " + sqlite_error(db, rc));
    auto read_meta = [&] {
        meta.clear();
        Statement m(db, "SELECT key, value FROM meta");
        while ((rc = m.step()) == SQLITE_ROW) meta[m.text(0)] = m.text(1);
        if (rc != SQLITE_DONE) throw Error(sqlite_error(db, rc));
    };
    try {
        read_meta();
    } catch (const std::runtime_error& e) {
        // A truncated file loses the index written last at the close, and SQLite then refuses
        // the whole schema; with writable_schema it reads the tables that are there (and this
        // reader writes nothing).
        try {
            exec(db, "PRAGMA writable_schema=ON");
            read_meta();
        } catch (const std::runtime_error&) {
            throw fail(std::string("not a cpm recording (") + e.what() + ")");
        }
    }
    if (meta["format"] != kRecordingFormat) throw fail("not a cpm recording (its meta table names no format '" + std::string(kRecordingFormat) + "')");
    if (meta["version"] != kRecordingVersion) throw fail("recording format version " + meta["version"] + ", this cpm reads version " + kRecordingVersion);
    return owner.release();
}

// ---- writing -------------------------------------------------------------------------------

struct RecordingWriter::Event
{
    enum Kind { added, sample, deleted } kind;
    Oid oid = kNoOid;
    uint64_t t0 = 0, t1 = 0, t2 = 0, t3 = 0, lost = 0;  // sample: commit, data, valid_after, source; deleted: t0
    ObjectInfo info;                                    // added
    std::vector<uint8_t> payload;                       // sample
};

namespace {

/// The meta every part of a recording begins with.
std::map<std::string, std::string> recording_meta(const RecordingOptions& o, uint64_t started_ns)
{
    char host[256] = {};
    ::gethostname(host, sizeof host - 1);
    return {{"name", o.name}, {"host", host}, {"started_ns", std::to_string(started_ns)}};
}

std::map<std::string, std::string> lab_idl()
{
    const IdlDecoder* lab = IdlDecoder::lab_types();
    return lab ? lab->sources() : std::map<std::string, std::string>{};
}

}  // namespace

RecordingWriter::RecordingWriter(std::string path, RecordingOptions options) : path_(std::move(path)), options_(std::move(options))
{
    started_ns_ = part_started_ns_ = cpm::get_time_ns();
    const bool split = options_.split_bytes || options_.split_ns;
    if (!split && options_.max_total_bytes) throw Error("recording " + path_ + ": a limit on all its files goes with a split");
    auto meta = recording_meta(options_, started_ns_);
    if (split) meta["part"] = "0";
    const std::string first = split ? part_path(0) : path_;
    file_ = create_recording_file(first, recording_format(path_, options_.format), meta, lab_idl(), options_.max_bytes, options_.foxglove_3d);
    parts_.push_back(first);
    thread_ = std::thread([this] { run(); });
}

std::string RecordingWriter::part_path(size_t part) const
{
    const std::filesystem::path p(path_);
    char n[16];
    std::snprintf(n, sizeof n, "_%03zu", part);
    return (p.parent_path() / (p.stem().string() + n + p.extension().string())).string();
}

std::vector<std::string> RecordingWriter::files() const
{
    std::lock_guard lock(mutex_);
    return parts_;
}

void RecordingWriter::split_if_due()
{
    if (!file_ || (!options_.split_bytes && !options_.split_ns)) return;
    const uint64_t now = cpm::get_time_ns();
    const bool due = (options_.split_bytes && file_->bytes() >= options_.split_bytes) || (options_.split_ns && now - part_started_ns_ >= options_.split_ns);
    if (!due) return;
    // The part ends here: every sample so far is in it, the next one begins with the next batch.
    file_->commit();
    file_->finish({{"ended_ns", std::to_string(now)}, {"samples", std::to_string(added_)}});
    const uint64_t in_file = file_->samples_in_file() > carried_ ? file_->samples_in_file() - carried_ : 0;
    file_.reset();
    std::string next;
    {
        std::lock_guard lock(mutex_);
        counters_.dropped += added_ > in_file ? added_ - in_file : 0;  // a last chunk the disk refused
        written_before_ += in_file;
        counters_.written = written_before_;
        next = part_path(part_count_);
    }
    added_ = 0;
    auto meta = recording_meta(options_, started_ns_);
    meta["part"] = std::to_string(part_count_++);
    meta["carried_samples"] = std::to_string(newest_kept_.size());
    file_ = create_recording_file(next, recording_format(path_, options_.format), meta, lab_idl(), options_.max_bytes, options_.foxglove_3d);
    part_started_ns_ = now;
    // It stands alone: every living object, the newest state of each transient-local one.
    for (const auto& [oid, info] : living_) file_->add_object(info);
    for (const auto& [oid, k] : newest_kept_) {
        file_->add_sample(oid, {.commit_ns = k.commit_ns, .data_ns = k.data_ns, .valid_after_ns = k.valid_after_ns, .source_ns = k.source_ns,
                                .payload = k.payload.data(), .size = k.payload.size()});
    }
    carried_ = newest_kept_.size();
    file_->commit();
    {
        std::lock_guard lock(mutex_);
        parts_.push_back(next);
    }
    // The oldest parts go while all of them hold more than the limit (never the one being written).
    if (!options_.max_total_bytes) return;
    uint64_t total = 0;
    std::vector<std::pair<std::string, uint64_t>> sizes;
    for (const auto& part : files()) {
        std::error_code ec;
        const uint64_t size = std::filesystem::file_size(part, ec);
        sizes.emplace_back(part, ec ? 0 : size);
        total += ec ? 0 : size;
    }
    for (size_t i = 0; i + 1 < sizes.size() && total > options_.max_total_bytes; ++i) {
        std::error_code ec;
        std::filesystem::remove(sizes[i].first, ec);
        total -= sizes[i].second;
        CPM_LOG_WARN("recording %s: deleted its oldest file %s (all its files held more than %llu bytes)", path_.c_str(), sizes[i].first.c_str(),
                     (unsigned long long)options_.max_total_bytes);
        std::lock_guard lock(mutex_);
        parts_.erase(std::find(parts_.begin(), parts_.end(), sizes[i].first));
    }
}

RecordingWriter::~RecordingWriter() { close(); }

void RecordingWriter::object_added(const ObjectInfo& info)
{
    std::lock_guard lock(mutex_);
    if (closing_ || failed_) return;
    Event e{Event::added};
    e.oid = info.oid;
    e.info = info;
    queue_.push_back(std::move(e));
}

void RecordingWriter::sample_committed(Oid oid, const Incoming& s, uint64_t commit_ns)
{
    std::lock_guard lock(mutex_);
    ++counters_.queued;
    if (closing_ || failed_ || queued_bytes_ + s.size > options_.max_queued_bytes) {
        if (!failed_ && !closing_ && counters_.dropped == 0) {
            CPM_LOG_ERROR("recording %s: the disk falls behind; samples are dropped from the recording (the live history keeps them)",
                          path_.c_str());
        }
        ++counters_.dropped;
        return;
    }
    Event e{Event::sample};
    e.oid = oid;
    e.t0 = commit_ns;
    e.t1 = s.data_ns;
    e.t2 = s.valid_after_ns;
    e.t3 = s.source_ns;
    e.lost = s.lost_before;
    e.payload.assign(s.data, s.data + s.size);
    queued_bytes_ += s.size;
    ++counters_.waiting;
    queue_.push_back(std::move(e));
    if (queue_.size() >= 4096) cv_.notify_one();
}

void RecordingWriter::object_deleted(Oid oid, uint64_t deleted_ns)
{
    std::lock_guard lock(mutex_);
    if (closing_ || failed_) return;
    Event e{Event::deleted};
    e.oid = oid;
    e.t0 = deleted_ns;
    queue_.push_back(std::move(e));
}

void RecordingWriter::run()
{
    // The disk writes yield to the ingest and the DDS threads: on a busy machine the queue takes
    // up the slack (bounded by max_queued_bytes) and the file catches up when it can.
    ::setpriority(PRIO_PROCESS, static_cast<id_t>(::syscall(SYS_gettid)), 10);
    std::unique_lock lock(mutex_);
    bool more = false;  // a batch was cut short: the rest is due at once
    for (;;) {
        cv_.wait_for(lock, std::chrono::nanoseconds(options_.flush_period_ns), [&] { return closing_ || more || queue_.size() >= 4096; });
        std::deque<Event> batch;
        if (!options_.split_bytes) {
            batch.swap(queue_);
            queued_bytes_ = 0;
        } else {
            // A part is checked for its size between batches: a batch of at most a quarter of a
            // part keeps each part within 1.25 times --record-split however far the disk fell
            // behind (one batch of 1 MB made a 128 kB part eight times too large).
            uint64_t bytes = 0;
            while (!queue_.empty() && (batch.empty() || bytes < options_.split_bytes / 4)) {
                bytes += queue_.front().payload.size();
                batch.push_back(std::move(queue_.front()));
                queue_.pop_front();
            }
            queued_bytes_ -= std::min(queued_bytes_, bytes);
        }
        counters_.waiting -= std::min<uint64_t>(counters_.waiting, uint64_t(std::count_if(batch.begin(), batch.end(), [](const Event& e) {
                                                      return e.kind == Event::sample;
                                                  })));
        more = !queue_.empty();
        const bool last = closing_ && !more;
        lock.unlock();
        bool ok = true;
        try {
            split_if_due();
        } catch (const std::exception& e) {
            fail(std::string("cannot begin its next file: ") + e.what());
            ok = false;
            const uint64_t lost = uint64_t(std::count_if(batch.begin(), batch.end(), [](const Event& e) { return e.kind == Event::sample; }));
            std::lock_guard dropped(mutex_);
            counters_.dropped += lost;
        }
        ok = ok && (batch.empty() || write(batch));
        lock.lock();
        if (!ok) {
            counters_.dropped += uint64_t(std::count_if(queue_.begin(), queue_.end(), [](const Event& e) { return e.kind == Event::sample; }));
            queue_.clear();
            counters_.waiting = 0;
        }
        if (last || failed_) return;
    }
}

bool RecordingWriter::write(std::deque<Event>& batch)
{
    const uint64_t added_before = added_;
    try {
        for (const Event& e : batch) {
            switch (e.kind) {
                case Event::added:
                    file_->add_object(e.info);
                    living_[e.oid] = e.info;
                    break;
                case Event::sample:
                    file_->add_sample(e.oid, {.commit_ns = e.t0,
                                              .data_ns = e.t1,
                                              .valid_after_ns = e.t2,
                                              .source_ns = e.t3,
                                              .lost_before = e.lost,
                                              .payload = e.payload.data(),
                                              .size = e.payload.size()});
                    ++added_;
                    if (options_.split_bytes || options_.split_ns) keep_if_transient_local(e);
                    break;
                case Event::deleted:
                    file_->delete_object(e.oid, e.t0);
                    living_.erase(e.oid);
                    newest_kept_.erase(e.oid);
                    break;
            }
        }
        file_->commit();
    } catch (const std::runtime_error& e) {
        // What did not reach the file is lost (SQLite rolls the batch back; MCAP loses its open
        // chunk and keeps the chunks before it).
        uint64_t in_batch = 0;
        for (const Event& ev : batch) in_batch += ev.kind == Event::sample;
        const uint64_t in_file = file_->samples_in_file() > carried_ ? file_->samples_in_file() - carried_ : 0;
        {
            std::lock_guard lock(mutex_);
            counters_.dropped += (in_batch - (added_ - added_before)) + (added_ > in_file ? added_ - in_file : 0);
            counters_.written = written_before_ + in_file;
        }
        added_ = in_file;
        fail(dynamic_cast<const RecordingFull*>(&e) ? e.what() : std::string("cannot write to it: ") + e.what());
        return false;
    }
    std::lock_guard lock(mutex_);
    counters_.written = written_before_ + (file_->samples_in_file() > carried_ ? file_->samples_in_file() - carried_ : 0);
    return !failed_;
}

void RecordingWriter::keep_if_transient_local(const Event& e)
{
    const auto o = living_.find(e.oid);
    if (o == living_.end()) return;
    const TopicSpec* t = topics::find(o->second.topic);
    if (!t || !t->writer.transient_local) return;
    newest_kept_[e.oid] = {e.t0, e.t1, e.t2, e.t3, e.payload};
}

void RecordingWriter::fail(const std::string& why)
{
    std::lock_guard lock(mutex_);
    if (failed_) return;
    failed_ = true;
    counters_.failed = true;
    counters_.error = "recording " + path_ + ": " + why + "; the recording stopped after " + std::to_string(counters_.written) +
                      " samples, which stay readable";
    CPM_LOG_ERROR("%s", counters_.error.c_str());
}

void RecordingWriter::close()
{
    {
        std::lock_guard lock(mutex_);
        if (closed_) return;
        closed_ = closing_ = true;
    }
    cv_.notify_one();
    if (thread_.joinable()) thread_.join();
    if (!file_) return;  // a split that could not begin its next file: the error says so
    // What the file holds once closed (an MCAP file's last chunk is written at its close).
    const RecordingCounters c = counters();
    try {
        file_->finish({{"ended_ns", std::to_string(cpm::get_time_ns())},
                       {"samples", std::to_string(added_)},
                       {"dropped", std::to_string(c.dropped)}});
    } catch (const std::exception& e) {
        fail(std::string("cannot close it: ") + e.what());
    }
    std::lock_guard lock(mutex_);
    const uint64_t in_file = file_->samples_in_file() > carried_ ? file_->samples_in_file() - carried_ : 0;
    counters_.dropped += added_ > in_file ? added_ - in_file : 0;
    counters_.written = written_before_ + in_file;
    file_.reset();
}

RecordingCounters RecordingWriter::counters() const
{
    std::lock_guard lock(mutex_);
    return counters_;
}

// ---- reading -------------------------------------------------------------------------------

namespace {

/// A store that keeps all a recording holds: a window and byte budgets nothing reaches.
StoreOptions keeping_everything()
{
    StoreOptions keep_all;
    keep_all.default_retention.window_ns = uint64_t(1) << 62;
    keep_all.default_retention.max_bytes_per_topic = std::numeric_limits<uint64_t>::max() / 4;
    keep_all.max_bytes_total = std::numeric_limits<uint64_t>::max() / 4;
    return keep_all;
}

/// The recording's name, start and (when it was closed) end from its meta table.
void read_meta(std::map<std::string, std::string>& meta, LoadedRecording& out)
{
    out.name = meta["name"];
    out.started_ns = std::strtoull(meta["started_ns"].c_str(), nullptr, 10);
    out.complete = meta.count("ended_ns") != 0;  // written by a clean close
    out.ended_ns = std::strtoull(meta["ended_ns"].c_str(), nullptr, 10);
}

/// The IDL the recording carries, and the decoder made of it; what does not read is damage.
void read_types(sqlite3* db, LoadedRecording& out, std::vector<std::string>& damage)
{
    try {
        Statement t(db, "SELECT file, idl FROM types");
        int rc;
        while ((rc = t.step()) == SQLITE_ROW) out.idl[t.text(0)] = t.text(1);
        if (rc != SQLITE_DONE) damage.push_back("its types table is damaged: " + sqlite_error(db, rc));
        if (!out.idl.empty()) out.types = std::make_shared<IdlDecoder>(out.idl);
    } catch (const std::runtime_error& e) {
        damage.push_back(std::string("its IDL does not read: ") + e.what());
    }
}

/// The objects as recorded, each with its deletion time (0: never), oldest first.
using RecordedObjects = std::vector<std::pair<ObjectInfo, uint64_t>>;

/// The objects table; the rows before a damaged one, and the damage. Throws when it does not read.
RecordedObjects read_objects(sqlite3* db, std::vector<std::string>& damage)
{
    Statement objects(db, "SELECT oid, kind, name, topic, key, type_name, parent, creator, creator_guid, created_ns, deleted_ns,"
                          " history_interval_ns, data_time FROM objects ORDER BY created_ns, oid");
    RecordedObjects rows;
    int rc;
    while ((rc = objects.step()) == SQLITE_ROW) {
        ObjectInfo i;
        i.oid = objects.u64(0);
        i.kind = objects.text(1) == "process" ? ObjectKind::process : ObjectKind::instance;
        i.name = objects.text(2);
        i.topic = objects.text(3);
        i.key = objects.text(4);
        i.type_name = objects.text(5);
        i.parent = objects.u64(6);
        i.creator = objects.text(7);
        i.creator_guid = objects.text(8);
        i.created_ts = objects.u64(9);
        i.history_interval_ns = objects.u64(11);
        i.data_time = objects.text(12);
        rows.emplace_back(std::move(i), objects.u64(10));
    }
    if (rc != SQLITE_DONE) damage.push_back("its objects table is damaged after " + std::to_string(rows.size()) + " objects: " + sqlite_error(db, rc));
    return rows;
}

/// Each recorded oid → the oid to restore it under. Where the live store gave a purged object's
/// slot to a later one, the later one keeps its oid (the one the live store answered with last)
/// and the earlier moves past every slot.
std::map<Oid, Oid> oids_to_restore(const RecordedObjects& rows)
{
    std::map<uint32_t, uint32_t> newest_generation;
    for (const auto& [i, deleted] : rows) {
        auto& g = newest_generation[uint32_t(i.oid)];
        g = std::max(g, uint32_t(i.oid >> 32));
    }
    uint32_t next_slot = newest_generation.empty() ? 1 : newest_generation.rbegin()->first + 1;
    std::map<Oid, Oid> oids;
    for (const auto& [i, deleted] : rows) oids[i.oid] = uint32_t(i.oid >> 32) == newest_generation[uint32_t(i.oid)] ? i.oid : next_slot++;
    return oids;
}

/// The oid a recorded one was loaded under; kNoOid for one not loaded.
Oid as_loaded(const std::map<Oid, Oid>& oids, Oid recorded)
{
    auto it = oids.find(recorded);
    return it == oids.end() ? kNoOid : it->second;
}

/// Puts the objects into the store (oids updated where the store gave another) and adds their
/// deletions, to be marked once the samples are in.
void restore_objects(Store& store, RecordedObjects& rows, std::map<Oid, Oid>& oids, std::vector<std::pair<Oid, uint64_t>>& deletions)
{
    for (auto& [i, deleted] : rows) {
        const Oid wanted = oids[i.oid];
        i.oid = wanted;
        i.parent = as_loaded(oids, i.parent);
        const Oid got = store.restore_object(std::move(i));
        if (deleted) deletions.emplace_back(got, deleted);
        if (got != wanted) {
            for (auto& [recorded, now] : oids) now = now == wanted ? got : now;
        }
    }
}

/// Commits every sample to its object in the order recorded, counting them (out.samples) and
/// keeping the newest commit time; samples after a damaged row are lost, and that is damage.
void read_samples(sqlite3* db, const std::map<Oid, Oid>& oids, LoadedRecording& out, uint64_t& newest, std::vector<std::string>& damage)
{
    Statement samples(db, "SELECT oid, commit_ns, data_ns, valid_after_ns, source_ns, lost_before, payload FROM samples ORDER BY rowid");
    int rc;
    while ((rc = samples.step()) == SQLITE_ROW) {
        const Oid oid = as_loaded(oids, samples.u64(0));
        Incoming in;
        in.data_ns = samples.u64(2);
        in.valid_after_ns = samples.u64(3);
        in.source_ns = samples.u64(4);
        in.lost_before = samples.u64(5);
        in.data = samples.blob(6);
        in.size = samples.bytes(6);
        const uint64_t commit = samples.u64(1);
        if (oid != kNoOid) out.store->commit(oid, in, commit);
        newest = std::max(newest, commit);
        ++out.samples;
    }
    if (rc != SQLITE_DONE) {
        damage.push_back("it is damaged after " + std::to_string(out.samples) + " samples (" + sqlite_error(db, rc) +
                         "); the samples before the damage answer");
    }
}

/// A recording not closed ends at its newest sample; it is complete when closed and undamaged,
/// and every damage is said in one warning naming the file.
void sum_up(LoadedRecording& out, uint64_t newest, std::vector<std::string> damage, const std::string& path)
{
    if (!out.complete) {
        damage.push_back("it was not closed (the recording process ended without closing it); it ends at its newest sample");
        out.ended_ns = newest;
    }
    out.complete = out.complete && damage.size() == 0;
    for (const auto& d : damage) out.warning += (out.warning.empty() ? "recording " + path + ": " : "; ") + d;
}

}  // namespace

LoadedRecording load_recording(const std::string& path)
{
    std::map<std::string, std::string> meta;
    std::unique_ptr<sqlite3, int (*)(sqlite3*)> db(open_recording_file(path, meta), sqlite3_close);
    LoadedRecording out;
    out.store = std::make_unique<Store>(keeping_everything());
    read_meta(meta, out);
    std::vector<std::string> damage;
    if (meta.count("damage")) damage.push_back(meta["damage"]);  // an MCAP file's, read up to it
    read_types(db.get(), out, damage);

    std::map<Oid, Oid> oids;  // as recorded → as loaded (differs only where the live store reused a slot)
    std::vector<std::pair<Oid, uint64_t>> deletions;
    uint64_t newest = 0;
    try {
        RecordedObjects rows = read_objects(db.get(), damage);
        oids = oids_to_restore(rows);
        restore_objects(*out.store, rows, oids, deletions);
        read_samples(db.get(), oids, out, newest, damage);
    } catch (const std::runtime_error& e) {
        if (oids.empty()) throw Error("recording " + path + ": its tables do not read: " + e.what());
        damage.push_back(std::string("it is damaged: ") + e.what());
    }
    for (const auto& [oid, t] : deletions) out.store->mark_deleted(oid, t);
    sum_up(out, newest, std::move(damage), path);
    return out;
}

namespace {

/// The samples with a create_stamp (not the source timestamp of a type without a Header).
constexpr const char* kStamped = "FROM samples s JOIN objects o ON o.oid = s.oid WHERE o.data_time = 'create_stamp'";

/// Data times below this are a lab clock's (from 0), not the wall clock of a recording that began at `started_ns`.
uint64_t lab_clock_limit(uint64_t started_ns) { return started_ns / 2; }

}  // namespace

RunClock recording_clock(const std::string& path)
{
    std::map<std::string, std::string> meta;
    std::unique_ptr<sqlite3, int (*)(sqlite3*)> db(open_recording_file(path, meta), sqlite3_close);
    RunClock c;
    c.started_ns = std::strtoull(meta["started_ns"].c_str(), nullptr, 10);
    if (meta.count("ended_ns")) {
        c.ended_ns = std::strtoull(meta["ended_ns"].c_str(), nullptr, 10);
    } else {
        Statement newest(db.get(), "SELECT max(commit_ns) FROM samples");
        c.ended_ns = newest.step() == SQLITE_ROW ? newest.u64(0) : c.started_ns;
    }
    // A simulated run's lab clock starts at 0: its data times lie decades before the commits. A
    // service beside it (the history's own status) may stamp with the wall clock: the lab clock's
    // span is that of the stamps before the recording started.
    Statement data(db.get(), (std::string("SELECT min(s.data_ns), max(s.data_ns), count(*) ") + kStamped + " AND s.data_ns < ?").c_str());
    data.bind(1, lab_clock_limit(c.started_ns));
    Statement all(db.get(), (std::string("SELECT min(s.data_ns), max(s.data_ns), count(*) ") + kStamped).c_str());
    const bool have_all = all.step() == SQLITE_ROW && all.u64(2) > 0;
    // Most stamps on a lab clock: a real run's stray unset create_stamp (0) does not make it one.
    if (data.step() == SQLITE_ROW && data.u64(2) > 0 && have_all && data.u64(2) * 2 > all.u64(2)) {
        c.lab_clock = true;
        c.data_first_ns = data.u64(0);
        c.data_last_ns = data.u64(1);
    } else if (have_all) {
        c.data_first_ns = all.u64(0);
        c.data_last_ns = all.u64(1);
    } else {
        c.data_first_ns = c.started_ns;
        c.data_last_ns = c.ended_ns;
    }
    return c;
}

bool is_time_into_run(const std::string& text)
{
    return !text.empty() && std::isdigit(static_cast<unsigned char>(text[0])) && text.find_first_not_of("0123456789") != std::string::npos &&
           text.find_first_of("-:") == std::string::npos;
}

uint64_t recording_time(const std::string& path, const RunClock& clock, const std::string& flag, const std::string& text, bool by_data)
{
    if (!is_time_into_run(text)) return cpm::cli::parse_time(flag, text, by_data ? clock.data_last_ns : clock.ended_ns);
    const uint64_t data = std::min<uint64_t>((clock.lab_clock ? 0 : clock.started_ns) + cpm::cli::parse_duration(flag, text), INT64_MAX);
    if (by_data) return data;
    // At or before the first stamp: the recording's start (samples without a stamp, state sent
    // before the first one, are in the run too).
    if (data <= clock.data_first_ns) return clock.started_ns;
    // A commit time: that of the first stamped sample at or after it on the run's clock.
    std::map<std::string, std::string> meta;
    std::unique_ptr<sqlite3, int (*)(sqlite3*)> db(open_recording_file(path, meta), sqlite3_close);
    Statement first(db.get(), (std::string("SELECT min(s.commit_ns) ") + kStamped + " AND s.data_ns >= ? AND s.data_ns < ?").c_str());
    first.bind(1, data).bind(2, clock.lab_clock ? lab_clock_limit(clock.started_ns) : uint64_t(INT64_MAX));
    if (first.step() == SQLITE_ROW && !first.null(0)) return first.u64(0);
    return clock.lab_clock ? clock.ended_ns + 1 : data;  // past the run's end
}

ExportCounts export_recording(const std::string& path, const std::string& out, const ExportOptions& o)
{
    std::map<std::string, std::string> meta;
    std::unique_ptr<sqlite3, int (*)(sqlite3*)> db(open_recording_file(path, meta), sqlite3_close);
    std::map<std::string, std::string> idl;
    {
        Statement t(db.get(), "SELECT file, idl FROM types");
        while (t.step() == SQLITE_ROW) idl[t.text(0)] = t.text(1);
    }
    std::vector<std::string> damage;
    RecordedObjects rows = read_objects(db.get(), damage);
    std::set<std::string> wanted(o.topics.begin(), o.topics.end()), held;
    for (const auto& [i, deleted] : rows) held.insert(i.topic);
    for (const auto& t : wanted) {
        if (!held.count(t)) throw Error("recording " + path + ": no topic '" + t + "' in it");
    }
    std::set<Oid> oids;
    std::map<std::string, std::string> begin;
    for (const char* k : {"name", "host", "started_ns"}) begin[k] = meta[k];
    ExportCounts counts;
    const RecordingFormat format = recording_format(out, o.format);
    auto file = create_recording_file(out, format, begin, idl, 0, o.foxglove_3d);
    try {
        for (const auto& [info, deleted] : rows) {
            if (info.kind == ObjectKind::instance && !wanted.empty() && !wanted.count(info.topic)) continue;
            file->add_object(info);
            oids.insert(info.oid);
            ++counts.objects;
        }
        const std::string by = o.by_data ? "data_ns" : "commit_ns";
        Statement samples(db.get(), ("SELECT oid, commit_ns, data_ns, valid_after_ns, source_ns, lost_before, payload FROM samples WHERE " + by +
                                     " >= ? AND " + by + " < ? ORDER BY rowid").c_str());
        samples.bind(1, std::min<uint64_t>(o.from_ns, INT64_MAX)).bind(2, std::min<uint64_t>(o.to_ns, INT64_MAX));
        while (samples.step() == SQLITE_ROW) {
            if (!oids.count(samples.u64(0))) continue;
            file->add_sample(samples.u64(0), {.commit_ns = samples.u64(1),
                                              .data_ns = samples.u64(2),
                                              .valid_after_ns = samples.u64(3),
                                              .source_ns = samples.u64(4),
                                              .lost_before = samples.u64(5),
                                              .payload = samples.blob(6),
                                              .size = samples.bytes(6)});
            if (++counts.samples % 4096 == 0) file->commit();
        }
        for (const auto& [info, deleted] : rows) {
            if (deleted && oids.count(info.oid)) file->delete_object(info.oid, deleted);
        }
        file->commit();
        std::map<std::string, std::string> end;
        for (const char* k : {"ended_ns", "samples", "dropped"}) {
            if (meta.count(k)) end[k] = meta[k];
        }
        if (meta.count("ended_ns")) end["samples"] = std::to_string(counts.samples);
        if (format == RecordingFormat::mcap) {
            for (const auto& [name, values] : o.metadata) file->add_metadata(name, values);
        }
        file->finish(end);
    } catch (const std::exception& e) {
        file.reset();
        std::filesystem::remove(out);
        throw Error("export to " + out + ": " + e.what());
    }
    return counts;
}

namespace {

class RecordingBackend final : public cpm::HistoryBackend
{
public:
    explicit RecordingBackend(std::shared_ptr<const LoadedRecording> r) : recording_(std::move(r)) {}
    HistoryReply request(const HistoryRequest& rq) override
    {
        if (!may_wait(rq)) return answer(*recording_->store, rq);
        HistoryRequest now = rq;
        now.timeout_ns(0);
        return answer(*recording_->store, now);
    }

private:
    std::shared_ptr<const LoadedRecording> recording_;
};

}  // namespace

std::unique_ptr<cpm::HistoryBackend> recording_backend(std::shared_ptr<const LoadedRecording> recording)
{
    return std::make_unique<RecordingBackend>(std::move(recording));
}

}  // namespace cpm::rtdb

cpm::HistoryClient cpm::HistoryClient::open_recording(const std::string& path)
{
    try {
        return HistoryClient(cpm::rtdb::recording_backend(std::make_shared<cpm::rtdb::LoadedRecording>(cpm::rtdb::load_recording(path))));
    } catch (const cpm::Error&) {
        throw;
    } catch (const std::exception& e) {
        throw cpm::Error(e.what());
    }
}
