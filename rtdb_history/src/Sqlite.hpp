#pragma once
// SQLite for the recording's writer, reader and player: a prepared statement finalized with
// its scope, and errors as text.
#include <cpm/Error.hpp>

#include <sqlite3.h>

#include <cstdint>
#include <map>
#include <string>
#include <vector>
#include <sys/stat.h>

namespace cpm::rtdb::sqlite {

/// A prepared statement, finalized with its scope. Throws cpm::Error with SQLite's message when
/// the SQL or a bound value is refused.
class Statement
{
public:
    Statement(sqlite3* db, const char* sql) : db_(db)
    {
        if (sqlite3_prepare_v2(db, sql, -1, &s_, nullptr) != SQLITE_OK) throw Error(sqlite3_errmsg(db));
    }
    ~Statement() { sqlite3_finalize(s_); }
    Statement(const Statement&) = delete;
    Statement& operator=(const Statement&) = delete;
    Statement& bind(int i, int64_t v) { return check(sqlite3_bind_int64(s_, i, v)); }
    Statement& bind(int i, uint64_t v) { return bind(i, static_cast<int64_t>(v)); }
    Statement& bind(int i, const std::string& v) { return check(sqlite3_bind_text(s_, i, v.data(), int(v.size()), SQLITE_TRANSIENT)); }
    Statement& bind_blob(int i, const void* data, size_t size)
    {
        return check(sqlite3_bind_blob(s_, i, size ? data : "", int(size), SQLITE_STATIC));
    }
    /// Runs a statement that returns no rows; false with the error when it failed.
    int run()
    {
        const int rc = sqlite3_step(s_);
        sqlite3_reset(s_);
        return rc == SQLITE_DONE ? SQLITE_OK : rc;
    }
    int step() { return sqlite3_step(s_); }
    uint64_t u64(int col) const { return static_cast<uint64_t>(sqlite3_column_int64(s_, col)); }
    bool null(int col) const { return sqlite3_column_type(s_, col) == SQLITE_NULL; }
    std::string text(int col) const
    {
        const auto* t = sqlite3_column_text(s_, col);
        return t ? std::string(reinterpret_cast<const char*>(t), size_t(sqlite3_column_bytes(s_, col))) : std::string();
    }
    const uint8_t* blob(int col) const { return static_cast<const uint8_t*>(sqlite3_column_blob(s_, col)); }
    size_t bytes(int col) const { return size_t(sqlite3_column_bytes(s_, col)); }

private:
    Statement& check(int rc)
    {
        if (rc != SQLITE_OK) throw Error(sqlite3_errmsg(db_));
        return *this;
    }
    sqlite3* db_;
    sqlite3_stmt* s_ = nullptr;
};

inline int exec(sqlite3* db, const std::string& sql) { return sqlite3_exec(db, sql.c_str(), nullptr, nullptr, nullptr); }

inline std::string sqlite_error(sqlite3* db, int rc)
{
    std::string e = sqlite3_errstr(rc);
    const char* m = db ? sqlite3_errmsg(db) : nullptr;
    if (m && e != m) e += std::string(" (") + m + ")";
    return e;
}

inline bool file_exists(const std::string& path)
{
    struct stat st{};
    return ::stat(path.c_str(), &st) == 0;
}

}  // namespace cpm::rtdb::sqlite

namespace cpm::rtdb {
/// Opens a recording for reading and reads its meta table; throws cpm::Error naming the
/// file when it is none (or of a format version this cpm does not read).
sqlite3* open_recording_file(const std::string& path, std::map<std::string, std::string>& meta);
/// The files a recording's name stands for: the file itself; for a folder, its split recording
/// (<stem>_NNN.db|.mcap) or its run's recording.db|.mcap; for names joined by '\n', each.
/// Throws cpm::Error naming what is wrong (no such file, a folder without one recording).
std::vector<std::string> recording_files(const std::string& path);
}  // namespace cpm::rtdb
