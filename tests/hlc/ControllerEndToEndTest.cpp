// Users' controllers in lab runs, with real processes: cpm lab run starts each controller on a
// domain of its own with its hlc_middleware; the summary counts what the middleware saw and the
// report's figures say what the cars did.
#include <cpm_test/Isolation.hpp>
#include <cpm_test/Process.hpp>
#include <cpm_test/TempDir.hpp>
#include <cpm_test/SourceDir.hpp>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <fstream>

using namespace std::chrono_literals;
using cpm_test::built_program;
using cpm_test::Process;
using cpm_test::TempDir;

namespace {

const std::string kRing = cpm_test::source_dir() + "/scenarios/lanes/ring.json";

nlohmann::json summary_of(const std::string& dir)
{
    std::ifstream in(dir + "/summary.json");
    return nlohmann::json::parse(in);
}

/// A scenario of `cars` cars on the ring driven by one controller (program and args as YAML).
std::string ring_scenario(const TempDir& dir, const std::string& time, const std::string& duration, int cars, const std::string& program,
                          const std::string& args, const std::string& driven)
{
    std::string text = "name: ring\ntime: " + time + "\nduration: " + duration + "\nlanes: " + kRing + "\nvehicles:\n";
    for (int i = 1; i <= cars; ++i) text += "  - {id: " + std::to_string(i) + "}\n";
    text += "controllers:\n  - program: " + program + "\n    name: ctl\n    args: " + args + "\n    vehicles: " + driven +
            "\n    period: 100ms\n    domain: " + std::to_string(cpm_test::extra_test_domain_id()) + "\n";
    return dir.write("ring.yaml", text);
}

/// Runs the scenario; the summary.
nlohmann::json run(const std::string& scenario, const std::string& out, std::chrono::seconds timeout = 120s)
{
    Process run({built_program("cpm"), "lab", "run", scenario, "--out", out, "--monitor", "off"});
    EXPECT_EQ(run.wait(timeout), 0) << run.output() << run.errors();
    return summary_of(out);
}

TEST(ControllerRun, ACppPlatoonControllerDrivesFourCarsOnTheRingAndEveryCommandGoesThrough)
{
    TempDir dir;
    const std::string out = dir.file("run");
    const auto s = run(ring_scenario(dir, "simulated", "12s", 4, "hlc_platoon", "[\"--lanes\", \"" + kRing + "\", \"--speed\", \"0.6\"]", "[1, 2, 3, 4]"), out);
    ASSERT_TRUE(s["ok"].get<bool>()) << s.dump(2);
    const auto& c = s["controllers"].at(0);
    EXPECT_EQ(c["controller"], "ctl");
    EXPECT_GE(c["periods"].get<int>(), 115) << c.dump(2);  // 12 s at 10 Hz, less the start
    EXPECT_EQ(c["answered"], c["periods"]) << "on the simulated clock every period waits for its answer: " << c.dump(2);
    EXPECT_EQ(c["unanswered"], 0) << c.dump(2);
    EXPECT_EQ(c["refused"], 0) << c.dump(2);
    EXPECT_GE(c["forwarded"].get<int>(), 4 * 110) << c.dump(2);
    EXPECT_GT(c["response_ms_p50"].get<double>(), 0.0) << c.dump(2);
    const auto& figures = s["report"];
    for (const char* id : {"1", "2", "3", "4"}) {
        // 0.6 m/s for about 11.5 s, from standing.
        EXPECT_GT(figures["cars"][id]["driven_m"].get<double>(), 5.0) << "car " << id << ": " << figures["cars"][id].dump();
    }
    EXPECT_GT(figures["min_distance_between_cars_m"].get<double>(), 0.45) << "no two cars closer than a car's length";
    std::ifstream page(out + "/report.html");
    const std::string html((std::istreambuf_iterator<char>(page)), {});
    EXPECT_NE(html.find("<h2>Controllers</h2>"), std::string::npos);
    EXPECT_NE(html.find("<tr><td>ctl</td><td>1, 2, 3, 4</td><td>" + c["periods"].dump() + "</td><td>" + c["answered"].dump() + "</td>"),
              std::string::npos)
        << "the report's row of the controller";
}

TEST(ControllerRun, APythonPlatoonControllerDrivesFourCarsOnTheRingAndEveryCommandGoesThrough)
{
    TempDir dir;
    const std::string out = dir.file("run");
    const auto s = run(ring_scenario(dir, "simulated", "12s", 4, cpm_test::source_dir() + "/examples/python/platoon.py",
                                     "[\"--lanes\", \"" + kRing + "\", \"--speed\", \"0.6\"]", "[1, 2, 3, 4]"),
                       out);
    ASSERT_TRUE(s["ok"].get<bool>()) << s.dump(2);
    const auto& c = s["controllers"].at(0);
    EXPECT_GE(c["periods"].get<int>(), 115) << c.dump(2);
    EXPECT_EQ(c["answered"], c["periods"]) << c.dump(2);
    EXPECT_EQ(c["refused"], 0) << c.dump(2);
    for (const char* id : {"1", "2", "3", "4"}) EXPECT_GT(s["report"]["cars"][id]["driven_m"].get<double>(), 5.0) << "car " << id;
    EXPECT_GT(s["report"]["min_distance_between_cars_m"].get<double>(), 0.45);
    std::ifstream log(out + "/controller_ctl.log");
    const std::string text((std::istreambuf_iterator<char>(log)), {});
    EXPECT_NE(text.find("\"failed\": 0"), std::string::npos) << "no step raised: " << text;
}

TEST(ControllerRun, AControllerThatSleepsPastItsPeriodHasItsStepsCancelledAndItsCarsStand)
{
    TempDir dir;
    const std::string out = dir.file("run");
    const auto s = run(ring_scenario(dir, "real", "6s", 2, built_program("test_controller"), "[\"--sleep\", \"350ms\"]", "[1, 2]"), out);
    const auto& c = s["controllers"].at(0);
    // Each step outlasts three periods: the lists that come meanwhile are cancelled, and what it
    // answers late answers a period already past.
    EXPECT_GT(c["unanswered"].get<int>(), c["periods"].get<int>() / 2) << c.dump(2);
    EXPECT_GT(c["refused_by_reason"]["past_period"].get<int>(), 10) << c.dump(2);
    EXPECT_EQ(c["forwarded"], 0) << c.dump(2);
    std::ifstream log(out + "/controller_ctl.log");
    const std::string text((std::istreambuf_iterator<char>(log)), {});
    EXPECT_NE(text.find("cancelled"), std::string::npos) << text;
    for (const char* id : {"1", "2"}) EXPECT_LT(s["report"]["cars"][id]["driven_m"].get<double>(), 0.05) << "car " << id << " moved";
}

TEST(ControllerRun, ACommandForACarTheControllerWasNotGivenIsRefusedCountedAndNamed)
{
    TempDir dir;
    const std::string out = dir.file("run");
    const auto s = run(ring_scenario(dir, "simulated", "4s", 2, built_program("test_controller"), "[\"--also_command\", \"2\"]", "[1]"), out);
    const auto& c = s["controllers"].at(0);
    EXPECT_GT(c["refused_by_reason"]["not_assigned"].get<int>(), 30) << c.dump(2);
    EXPECT_EQ(c["first_refusals"]["not_assigned"], "vehicle 2 is not assigned to this controller (it drives 1)") << c.dump(2);
    EXPECT_GT(c["forwarded"].get<int>(), 30) << "its own car's commands go through: " << c.dump(2);
    EXPECT_GT(s["report"]["cars"]["1"]["driven_m"].get<double>(), 0.5);
    EXPECT_LT(s["report"]["cars"]["2"]["driven_m"].get<double>(), 0.05) << "car 2 stood";
    std::ifstream log(out + "/hlc_ctl.log");
    const std::string text((std::istreambuf_iterator<char>(log)), {});
    EXPECT_NE(text.find("refused a command (not_assigned): vehicle 2 is not assigned"), std::string::npos) << text;
}

TEST(ControllerRun, AControllerThatCrashesEndsTheRunNamedWithTheEndOfItsLog)
{
    TempDir dir;
    const std::string out = dir.file("run");
    Process run({built_program("cpm"), "lab", "run",
                 ring_scenario(dir, "simulated", "20s", 2, built_program("test_controller"), "[\"--crash_after\", \"30\"]", "[1, 2]"), "--out", out,
                 "--monitor", "off"});
    EXPECT_NE(run.wait(120s), 0);
    const auto s = summary_of(out);
    EXPECT_FALSE(s["ok"].get<bool>());
    const std::string error = s["error"];
    EXPECT_NE(error.find("controller_ctl"), std::string::npos) << error;
    EXPECT_NE(error.find("crashing on purpose in step 30"), std::string::npos) << "the end of its log: " << error;
    EXPECT_LT(s["lab_time_s"].get<double>(), 10.0) << "the run ended when the controller died";
    EXPECT_EQ(s["controllers"].at(0)["answered"], 29) << s["controllers"].dump(2);
}

}  // namespace
