#include <cpm_test/Process.hpp>
#include <cpm_test/SourceDir.hpp>

#include <cpm_test/Isolation.hpp>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include <unistd.h>

namespace cpm_test {

namespace {

std::string temp_file(const char* prefix)
{
    std::string path = std::string("/tmp/") + prefix + "XXXXXX";
    const int fd = ::mkstemp(path.data());
    if (fd < 0) throw std::runtime_error("mkstemp failed");
    ::close(fd);
    return path;
}

cpm::ChildProcess start(std::vector<std::string> argv, std::vector<std::string> env, const std::string& out, const std::string& err)
{
    test_domain_id();  // children inherit CPM_DOMAIN_ID
    return cpm::ChildProcess(
        {.argv = std::move(argv), .env = std::move(env), .stdout_path = out, .stderr_path = err, .own_process_group = true});
}

}  // namespace

std::string file_text(const std::string& path)
{
    std::ifstream in(path);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

Process::Process(std::vector<std::string> argv, std::vector<std::string> env)
    : out_path_(temp_file("cpm_test_out_")), err_path_(temp_file("cpm_test_err_")),
      child_(start(std::move(argv), std::move(env), out_path_, err_path_))
{
}

Process::~Process()
{
    child_.stop();
    ::unlink(out_path_.c_str());
    ::unlink(err_path_.c_str());
}

int Process::wait(std::chrono::milliseconds timeout)
{
    const auto end = child_.wait(timeout);
    return end && end->signal == 0 ? end->code : -1;
}

std::string Process::output() const { return file_text(out_path_); }

std::string Process::errors() const { return file_text(err_path_); }

void Process::kill(int signal) { child_.signal(signal); }  // its whole process group: wrappers spawn children

int pid_with(const std::string& needle, const std::string& tag)
{
    auto text_of = [](const std::filesystem::path& file) {
        // A process may end while it is read: libstdc++ then throws (ESRCH), and it is no match.
        std::string text = file_text(file.string());
        std::replace(text.begin(), text.end(), '\0', ' ');
        return text + ' ';
    };
    for (const auto& e : std::filesystem::directory_iterator("/proc")) {
        const std::string name = e.path().filename();
        if (name.find_first_not_of("0123456789") != std::string::npos) continue;
        if (text_of(e.path() / "cmdline").find(needle) == std::string::npos) continue;
        if (tag.empty() || text_of(e.path() / "environ").find(tag + ' ') != std::string::npos) return std::stoi(name);
    }
    return 0;
}

std::string built_program(const std::string& name) { return std::string(CPM_BIN_DIR) + "/" + name; }

std::string source_dir() { return CPM_SOURCE_DIR; }

}  // namespace cpm_test
