// A test helper: keep-all reliable VehicleState writers torn down with unacknowledged samples.
// It matches a reader (prints "matched"), waits --pause for the test to freeze that reader
// (SIGSTOP), then --rounds times: a new writer, --cars × its window of samples that the frozen
// reader never acknowledges, the writer destroyed; prints "round N destroyed in M ms" each.
//   keep_all_writer TOPIC [--rounds 10] [--cars 50] [--pause 1s]     (domain from CPM_DOMAIN_ID)
#include <cpm/CommandLine.hpp>
#include <cpm/Participant.hpp>
#include <cpm/Writer.hpp>

#include <VehicleState.h>

#include <chrono>
#include <cstdio>
#include <optional>
#include <thread>

namespace {

const char* kHelp =
    "usage: keep_all_writer TOPIC [--rounds 10] [--cars 50] [--pause 1s]\n"
    "Matches a reader of TOPIC (prints \"matched\"), waits --pause, then --rounds times writes --cars x 1024\n"
    "VehicleStates with a keep-all reliable writer and destroys it, printing how long each destruction took.\n";

int run(int argc, char** argv)
{
    const auto args = cpm::cli::parse_args(std::vector<std::string>(argv + 1, argv + argc),
                                           {{"--rounds", true}, {"--cars", true}, {"--pause", true}}, "keep_all_writer");
    if (args.positional.size() != 1) throw cpm::cli::UsageError("keep_all_writer: give one TOPIC");
    const std::string topic = args.positional[0];
    const auto rounds = cpm::cli::parse_integer("--rounds", args.get("--rounds", "10"), 1, 1000);
    const auto cars = cpm::cli::parse_integer("--cars", args.get("--cars", "50"), 1, 255);
    const auto pause_ns = cpm::cli::parse_duration("--pause", args.get("--pause", "1s"));
    const cpm::WriterOptions options{.reliable = true, .keep_all = true};
    cpm::Participant& participant = cpm::Participant::default_participant();
    {
        cpm::Writer<VehicleState> first(participant, topic, options);
        if (!first.wait_for_matched(1, std::chrono::seconds(20))) {
            std::fprintf(stderr, "keep_all_writer: no reader of %s matched within 20 s\n", topic.c_str());
            return 1;
        }
        std::printf("matched\n");
        std::fflush(stdout);
        std::this_thread::sleep_for(std::chrono::nanoseconds(pause_ns));
    }
    for (long long r = 0; r < rounds; ++r) {
        std::optional<cpm::Writer<VehicleState>> writer;
        writer.emplace(participant, topic, options);
        (void)writer->wait_for_matched(1, std::chrono::seconds(5));  // the frozen reader, known from before
        VehicleState s;
        for (long long car = 1; car <= cars; ++car) {
            s.vehicle_id(uint8_t(car));
            for (int i = 0; i < 1024; ++i) {
                s.pose().x(i);
                (void)writer->write(s);
            }
        }
        const auto t0 = std::chrono::steady_clock::now();
        writer.reset();
        std::printf("round %lld destroyed in %lld ms\n", r, (long long)std::chrono::duration_cast<std::chrono::milliseconds>(
                                                              std::chrono::steady_clock::now() - t0).count());
        std::fflush(stdout);
    }
    return 0;
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "keep_all_writer", kHelp, run); }
