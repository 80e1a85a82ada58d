#include <cpm/Logging.hpp>

#include <cpm/AsyncReader.hpp>
#include <cpm/Error.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/init.hpp>

#include "lab_topics.hpp"

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
    Impl()
        : node_id(init_settings().node_id),
          log_writer(Participant::default_participant(), "log", log_options()),
          level_reader(
              [this](std::vector<LogLevel>& levels) {
                  for (const auto& l : levels) {
                      if (l.log_level() >= 1 && l.log_level() <= 4) level = l.log_level();
                  }
              },
              Participant::default_participant(), "logLevel", level_options())
    {
        if (const char* path = std::getenv("CPM_LOG_FILE"); path != nullptr && *path != '\0') open_file(path);
    }

    // The last 100 messages stay available to monitors that start late; a node that starts
    // late gets the lab's current level.
    static WriterOptions log_options() { return detail::reliable_writer_options(100, true); }
    static ReaderOptions level_options() { return detail::reliable_reader_options(1, true); }

    void open_file(const std::string& path)
    {
        std::FILE* f = std::fopen(path.c_str(), "a");
        if (f == nullptr) throw Error("Logging: cannot open log file '" + path + "': " + std::strerror(errno));
        std::lock_guard<std::mutex> lock(file_mutex);
        if (file != nullptr) std::fclose(file);
        file = f;
    }

    const std::string node_id;
    std::atomic<uint16_t> level{static_cast<uint16_t>(Severity::info)};
    std::mutex file_mutex;
    std::FILE* file = nullptr;
    Writer<Log> log_writer;
    AsyncReader<LogLevel> level_reader;  // last: its thread uses the members above
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
    impl_->log_writer.write(log);
}

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
