// A simulated run repeats sample for sample: each shipped scenario run twice on the simulated
// clock records the same samples on every topic but the clock's own traffic (and the log and
// the history's status, which carry wall-clock times), as `cpm history diff` compares them.
// Run beside the other tests on purpose: a machine busy with them must not change a run.
#include <cpm_test/Process.hpp>
#include <cpm_test/TempDir.hpp>

#include <nlohmann/json.hpp>

#include <gtest/gtest.h>

#include <fstream>

using namespace std::chrono_literals;
using cpm_test::built_program;
using cpm_test::Process;

namespace {

/// Runs the shipped scenario `name` twice in simulated time (`extra` flags too), then diffs the
/// two recordings with cpm history.
void expect_two_runs_alike(const std::string& name, std::vector<std::string> extra = {})
{
    cpm_test::TempDir dir;
    const std::string file = std::string(CPM_SOURCE_DIR) + "/scenarios/labs/" + name + ".yaml";
    for (const char* run : {"a", "b"}) {
        std::vector<std::string> argv{built_program("cpm"), "lab", "run", file, "--time", "simulated", "--out", dir.file(run), "--monitor", "off"};
        argv.insert(argv.end(), extra.begin(), extra.end());
        Process p(argv);
        ASSERT_EQ(p.wait(200s), 0) << p.output() << p.errors();
        std::ifstream summary(dir.file(run) + "/summary.json");
        const auto s = nlohmann::json::parse(summary);
        ASSERT_EQ(s["ok"], true) << s.dump(2);
        const double clock_s = s["clock_real_s"].get<double>();
        EXPECT_GT(clock_s, 0) << "a simulated run says how long its clock stepped";
        EXPECT_LT(clock_s, s["real_s"].get<double>());
        std::printf("%s run %s: %.1f s of lab time in %.1f s, the clock stepping %.1f s (%.1fx real time)\n", name.c_str(), run,
                    s["lab_time_s"].get<double>(), s["real_s"].get<double>(), clock_s, s["lab_time_s"].get<double>() / clock_s);
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
TEST(Repeat, TheEightCarIntersectionRunTwiceRecordsTheSameSamples) { expect_two_runs_alike("intersection", {"--duration", "40s"}); }
