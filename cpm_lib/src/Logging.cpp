#include <cpm/Logging.hpp>

#include <cpm/AsyncReader.hpp>
#include <cpm/Error.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/init.hpp>
#include <cpm/topics.hpp>

#include "UntilExit.hpp"

#include <Log.h>
#include <LogLevel.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <vector>

namespace cpm {

namespace {

const char* name_of(Severity s)
{
    switch (s) {
        case Severity::error: return "error";
        case Severity::warn: return "warn";
        case Severity::info: return "info";
        case Severity::debug: return "debug";
    }
    return "?";
}

std::string csv_quoted(const std::string& text)
{
    std::string out = "\"";
    for (char c : text) out += (c == '"') ? std::string("\"\"") : std::string(1, c);
    return out + "\"";
}

}  // namespace

struct Logging::Impl
{
    Impl() : node_id(init_settings().node_id)
    {
        if (const char* path = std::getenv("CPM_LOG_FILE"); path != nullptr && *path != '\0') open_file(path);
    }

    // The last 100 messages stay available to monitors that start late; a node that starts
    // late gets the lab's current level.

    void open_file(const std::string& path)
    {
        std::FILE* f = std::fopen(path.c_str(), "a");
        if (f == nullptr) throw Error("Logging: cannot open log file '" + path + "': " + std::strerror(errno));
        std::lock_guard<std::mutex> lock(file_mutex);
        if (file != nullptr) std::fclose(file);
        file = f;
    }

    /// The log's DDS entities on the default participant.
    struct Dds
    {
        explicit Dds(std::atomic<uint16_t>& level)
            : log_writer(Participant::default_participant(), topics::log.name, topics::log.writer),
              level_reader(
                  [&level](std::vector<LogLevel>& levels) {
                      for (const auto& l : levels) {
                          if (l.log_level() >= 1 && l.log_level() <= 4) level = l.log_level();
                      }
                  },
                  Participant::default_participant(), topics::log_level.name, topics::log_level.reader)
        {
        }
        Writer<Log> log_writer;
        AsyncReader<LogLevel> level_reader;
    };

    /// Creates the DDS entities if no thread has begun to. Nobody waits for another thread's
    /// creation: the waiting thread may be a reader's listener, holding the very reader that
    /// Fast DDS pairs a new writer with — a deadlock. Messages written meanwhile wait in
    /// `pending` and are published once the writer exists.
    void start()
    {
        if (creating.exchange(true)) return;
        std::unique_ptr<Dds> d;
        try {
            d = std::make_unique<Dds>(level);  // destroyed at exit (UntilExit), the log itself never
        } catch (const std::exception& e) {
            std::fprintf(stderr, "[error] %s: Logging: no `log` topic (%s); messages go to stderr and the file only\n",
                         node_id.c_str(), e.what());
        }
        std::vector<Log> waiting;
        {
            std::lock_guard<std::mutex> lock(pending_mutex);
            failed = d == nullptr;
            if (d) dds.set(std::move(d));
            waiting.swap(pending);
        }
        if (auto use = dds.use()) {
            for (const auto& w : waiting) (void)use->log_writer.write(w);
        }
    }

    void publish(const Log& log)
    {
        for (;;) {
            if (auto use = dds.use()) {
                (void)use->log_writer.write(log);  // never under pending_mutex: a reader in this process may log from the write
                return;
            }
            std::lock_guard<std::mutex> lock(pending_mutex);
            if (failed || dds.closed()) return;  // no topic, or the process is exiting: stderr and the file only
            if (!dds.is_set()) {
                pending.push_back(log);
                return;
            }
            // set meanwhile: written outside the lock
        }
    }

    const std::string node_id;
    std::atomic<uint16_t> level{static_cast<uint16_t>(Severity::info)};
    std::mutex file_mutex;
    std::FILE* file = nullptr;
    detail::UntilExit<Dds> dds;
    std::atomic<bool> creating{false};
    std::mutex pending_mutex;
    std::vector<Log> pending;  ///< under pending_mutex, while another thread creates `dds`
    bool failed = false;       ///< under pending_mutex
};

Logging& Logging::instance()
{
    // Never destroyed: messages may be written until the very end of the process.
    static Logging* logging = new Logging();
    return *logging;
}

Logging::Logging() : impl_(std::make_unique<Impl>()) {}

Logging::~Logging()
{
    if (impl_->file != nullptr) std::fclose(impl_->file);
}

void Logging::write(Severity severity, const char* format, ...)
{
    va_list args;
    va_start(args, format);
    vwrite(severity, format, args);
    va_end(args);
}

void Logging::vwrite(Severity severity, const char* format, va_list args)
{
    impl_->start();  // also the logLevel reader, so that a level change can let this message's kind pass
    if (static_cast<uint16_t>(severity) > impl_->level.load()) return;
    char buffer[2048];
    std::vsnprintf(buffer, sizeof buffer, format, args);
    const std::string content = buffer;
    const uint64_t now = get_time_ns();

    std::fprintf(stderr, "[%s] %llu %s: %s\n", name_of(severity), static_cast<unsigned long long>(now),
                 impl_->node_id.c_str(), content.c_str());
    {
        std::lock_guard<std::mutex> lock(impl_->file_mutex);
        if (impl_->file != nullptr) {
            std::fprintf(impl_->file, "%llu,%s,%s,%s\n", static_cast<unsigned long long>(now),
                         csv_quoted(impl_->node_id).c_str(), name_of(severity), csv_quoted(content).c_str());
            std::fflush(impl_->file);
        }
    }
    Log log;
    log.id(impl_->node_id);
    log.content(content);
    log.stamp().nanoseconds(now);
    log.log_level(static_cast<uint16_t>(severity));
    impl_->publish(log);
}

void Logging::connect() { impl_->start(); }

void Logging::set_level(Severity level) { impl_->level = static_cast<uint16_t>(level); }

Severity Logging::level() const { return static_cast<Severity>(impl_->level.load()); }

void Logging::set_file(const std::string& path)
{
    if (path.empty()) {
        std::lock_guard<std::mutex> lock(impl_->file_mutex);
        if (impl_->file != nullptr) std::fclose(impl_->file);
        impl_->file = nullptr;
        return;
    }
    impl_->open_file(path);
}

}  // namespace cpm
