// For the Python tests: every lab topic type read by a typed C++ reader from "py_in_<Type>" and
// written back by a typed C++ writer on "py_out_<Type>", until SIGINT/SIGTERM. Proves a Python
// sample is what a C++ program reads, field for field, and back.
#include <cpm/AsyncReader.hpp>
#include <cpm/CommandLine.hpp>
#include <cpm/Writer.hpp>
#include <cpm/init.hpp>

#include <cpm_topic_types.hpp>

#include <sys/prctl.h>

#include <chrono>
#include <csignal>
#include <cstdio>
#include <memory>
#include <thread>
#include <vector>

namespace {

struct Echo
{
    virtual ~Echo() = default;
};

template <class T>
struct EchoOf : Echo
{
    cpm::Writer<T> out;
    cpm::AsyncReader<T> in;
    explicit EchoOf(const std::string& name)
        : out("py_out_" + name, cpm::WriterOptions{.reliable = true, .keep_all = true}),
          in([this, name](std::vector<T>& samples) {
              // The test's reader found this writer, but this writer may not have found the
              // reader yet (discovery is per side): a sample written before then is not delivered.
              if (!out.wait_for_matched(1, std::chrono::seconds(10))) std::fprintf(stderr, "py_echo: no reader of py_out_%s in 10 s\n", name.c_str());
              for (const auto& s : samples) (void)out.write(s);
          },
             "py_in_" + name, cpm::ReaderOptions{.reliable = true, .keep_all = true})
    {
    }
};

}  // namespace

int main(int argc, char** argv)
{
    cpm::init(argc, argv);
    cpm::cli::stop_on_signals();
    ::prctl(PR_SET_PDEATHSIG, SIGTERM);  // never outlives the test that started it
    std::vector<std::unique_ptr<Echo>> echoes;
#define CPM_PY_TOPIC(T) echoes.push_back(std::make_unique<EchoOf<T>>(#T));
#include <topic_types.inc>
#undef CPM_PY_TOPIC
    std::printf("echoing %zu types\n", echoes.size());
    std::fflush(stdout);
    while (!cpm::cli::stop_requested()) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    return 0;
}
