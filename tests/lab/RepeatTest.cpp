// A simulated run repeats sample for sample: each shipped scenario run twice on the simulated
// clock records the same samples on every topic but the clock's own traffic (and the log and
// the history's status, which carry wall-clock times), as `cpm history diff` compares them.
// Run beside the other tests on purpose: a machine busy with them must not change a run. Nor
// must a recorder that falls behind: the intersection's second run pauses it mid-run.
#include <cpm_test/Isolation.hpp>
#include <cpm_test/Process.hpp>
#include <cpm_test/TempDir.hpp>
#include <cpm_test/SourceDir.hpp>

#include <cpm/rtdb/Recording.hpp>

#include <nlohmann/json.hpp>

#include <gtest/gtest.h>

#include <csignal>
#include <filesystem>
#include <fstream>
#include <thread>

using namespace std::chrono_literals;
using cpm_test::built_program;
using cpm_test::Process;

namespace {

/// Once the run's recording holds `bytes`, stops its recorder (cpm_history) for `pause`: a
/// recorder that a busy machine leaves behind the clock. Returns whether it did.
bool pause_recorder(const std::string& run_dir, uintmax_t bytes, std::chrono::milliseconds pause)
{
    const std::string file = run_dir + "/recording.db";
    std::error_code ec;
    if (!cpm_test::wait_until([&] { return std::filesystem::file_size(file, ec) >= bytes && !ec; }, 60s)) return false;
    const int pid = cpm_test::pid_with("--record " + file + " ");
    if (pid == 0 || ::kill(pid, SIGSTOP) != 0) return false;
    std::this_thread::sleep_for(pause);
    return ::kill(pid, SIGCONT) == 0;
}

/// Runs the shipped scenario `name` twice in simulated time (`extra` flags too), then diffs the
/// two recordings with cpm history. With `pause_in_b`, the second run's recorder is stopped for
/// 1.5 s (real time) a quarter into the recording. `steps` (if given) is how many steps the
/// first run's clock must have made (its triggers, the stops among them).
void expect_two_runs_alike(const std::string& name, std::vector<std::string> extra = {}, bool pause_in_b = false,
                           std::optional<uint64_t> steps = std::nullopt)
{
    cpm_test::TempDir dir;
    const std::string file = cpm_test::source_dir() + "/scenarios/labs/" + name + ".yaml";
    for (const char* run : {"a", "b"}) {
        std::vector<std::string> argv{built_program("cpm"), "lab", "run", file, "--time", "simulated", "--out", dir.file(run), "--monitor", "off"};
        argv.insert(argv.end(), extra.begin(), extra.end());
        Process p(argv);
        if (pause_in_b && std::string(run) == "b") {
            // 11 MB for 40 s of the intersection: paused about 10 s into its lab time.
            EXPECT_TRUE(pause_recorder(dir.file(run), 3'000'000, 1500ms)) << "the run ended before its recording held 3 MB\n" << p.errors();
        }
        ASSERT_EQ(p.wait(200s), 0) << p.output() << p.errors();
        std::ifstream summary(dir.file(run) + "/summary.json");
        const auto s = nlohmann::json::parse(summary);
        ASSERT_EQ(s["ok"], true) << s.dump(2);
        // Every sample the nodes wrote reached the recorder: none missing from any writer's
        // numbering. Only a stalled recorder may miss some of the clock's own announcements and
        // triggers, whose writers keep only their newest (the one that counts, keep-last 1).
        for (const auto& [topic, lost] : s["recording"]["lost_by_topic"].items()) {
            const bool clock_traffic = topic == "readyStatus" || topic == "systemTrigger";
            EXPECT_TRUE(pause_in_b && std::string(run) == "b" && clock_traffic)
                << "run " << run << " lost " << lost << " samples of " << topic << ": " << s["recording"].dump();
        }
        const double clock_s = s["clock_real_s"].get<double>();
        EXPECT_GT(clock_s, 0) << "a simulated run says how long its clock stepped";
        EXPECT_LT(clock_s, s["real_s"].get<double>());
        std::printf("%s run %s: %.1f s of lab time in %.1f s, the clock stepping %.1f s (%.1fx real time)\n", name.c_str(), run,
                    s["lab_time_s"].get<double>(), s["real_s"].get<double>(), clock_s, s["lab_time_s"].get<double>() / clock_s);
    }
    if (steps) {
        const auto rec = cpm::rtdb::load_recording(dir.file("a") + "/recording.db");
        const auto triggers = rec.store->find("systemTrigger", "");
        ASSERT_TRUE(triggers) << "the clock's steps are recorded";
        EXPECT_EQ(rec.store->info(*triggers)->samples_total, *steps) << "the clock's steps (its triggers, the stops among them)";
    }
    Process diff({built_program("cpm"), "history", "--file", dir.file("a"), "diff", dir.file("b")});
    EXPECT_EQ(diff.wait(60s), 0) << diff.output() << diff.errors();
    EXPECT_NE(diff.output().find(": identical"), std::string::npos) << diff.output();
    // Not a comparison of nothing: the cars' states are among what was compared.
    Process states({built_program("cpm"), "history", "--file", dir.file("a"), "diff", dir.file("b"), "--topics", "vehicleState", "--json"});
    ASSERT_EQ(states.wait(60s), 0) << states.output() << states.errors();
    const auto counts = nlohmann::json::parse(states.output());
    EXPECT_GE(counts["equal_samples"].get<uint64_t>(), 1000u) << states.output();
}

}  // namespace

TEST(Repeat, TheCorridorRunTwiceRecordsTheSameSamples) { expect_two_runs_alike("corridor"); }

TEST(Repeat, TheGatesCourseWithItsCameraAndMarkerFinderRunTwiceRecordsTheSameSamples)
{
    expect_two_runs_alike("gates", {"--duration", "40s"});
}

// 40 of its 120 s: the cars meet in the intersection within them (and the suite saves a minute).
// The second run's recorder is paused for 1.5 s mid-run (a machine too busy for it): the clock
// waits for it, and the recording loses none of the nodes' samples (without that wait it lost about
// 9000 in a second). Its clock steps each car's simulator and bridge in one step, 1 ms into every
// 20 ms, the recorder's tick (every 100 ms) and the planner's (every 400 ms) among them: 2000 steps,
// and the stop, sent twice (when the clock ends and when the run stops). With the bridge a step
// after the simulator and the recorder at the period's start there were 4002; with the planner at
// the period's start, 2102.
TEST(Repeat, TheEightCarIntersectionRunTwiceRecordsTheSameSamples)
{
    expect_two_runs_alike("intersection", {"--duration", "40s"}, /*pause_in_b=*/true, /*steps=*/2002);
}
