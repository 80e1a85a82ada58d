#pragma once
#include <cstdarg>
#include <cstdint>
#include <memory>
#include <string>

namespace cpm {

/// Severity of a log message; a message is kept when its level <= the current level.
enum class Severity : uint16_t { error = 1, warn = 2, info = 3, debug = 4 };

/// The process's log (cpm_lab's Logging): levelled printf-style messages stamped with the node
/// id and the lab time (cpm::get_time_ns), written to stderr, to a CSV file if one is set, and
/// to the `log` topic (reliable, transient-local: a monitor that starts late still gets the
/// last 100). A `LogLevel` sample on `logLevel` changes the level of every node at run time.
/// Thread-safe; never throws from write. The topic's writer (and the logLevel reader) are
/// created on the default participant by the first thread that writes; what other threads
/// write meanwhile is queued and published after, never waited for (a reader callback that
/// waited would deadlock Fast DDS, which pairs the new writer with that callback's reader).
class Logging
{
public:
    static Logging& instance();

    /// Writes one message if `severity` is within the current level.
    void write(Severity severity, const char* format, ...) __attribute__((format(printf, 3, 4)));
    void vwrite(Severity severity, const char* format, va_list args);

    /// Creates the log's DDS entities now, if no thread has begun to, instead of at the first
    /// message. Creating a DDS entity waits for what holds the process's readers (a reader's
    /// callback, a write stalled inside one): a loop that must never wait on DDS (a simulated
    /// microcontroller, a car's serial loop) calls this before it starts.
    void connect();

    void set_level(Severity level);
    Severity level() const;
    /// Also append messages as CSV (`time_ns,node_id,level,"message"`) to this file; an empty
    /// path stops writing a file. Throws cpm::Error naming the path when it cannot be opened.
    void set_file(const std::string& path);

    ~Logging();
    Logging(const Logging&) = delete;
    Logging& operator=(const Logging&) = delete;

private:
    Logging();
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace cpm

/// Shorthands: CPM_LOG_INFO("vehicle %d lost", id) and so on.
#define CPM_LOG_ERROR(...) ::cpm::Logging::instance().write(::cpm::Severity::error, __VA_ARGS__)
#define CPM_LOG_WARN(...) ::cpm::Logging::instance().write(::cpm::Severity::warn, __VA_ARGS__)
#define CPM_LOG_INFO(...) ::cpm::Logging::instance().write(::cpm::Severity::info, __VA_ARGS__)
#define CPM_LOG_DEBUG(...) ::cpm::Logging::instance().write(::cpm::Severity::debug, __VA_ARGS__)
