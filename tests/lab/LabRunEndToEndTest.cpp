// cpm lab run with real processes: a short corridor run gives its folder (a log per process, a
// recording that answers, summary.json); a node killed mid-run is named with the end of its log
// and the run fails; Ctrl-C stops everything and leaves a readable recording; a wrong scenario
// starts nothing.
#include <cpm/rtdb/Mcap.hpp>
#include <cpm/rtdb/Recording.hpp>
#include <cpm/timer_ids.hpp>

#include <cpm_test/Isolation.hpp>
#include <cpm_test/McapCheck.hpp>
#include <cpm_test/Process.hpp>
#include <cpm_test/TempDir.hpp>
#include <cpm_test/SourceDir.hpp>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>

using namespace std::chrono_literals;
using cpm_test::built_program;
using cpm_test::pid_with;
using cpm_test::Process;
using cpm_test::TempDir;
namespace fs = std::filesystem;

namespace {

const std::string kCorridor = cpm_test::source_dir() + "/scenarios/labs/corridor.yaml";

nlohmann::json summary_of(const std::string& dir)
{
    std::ifstream in(dir + "/summary.json");
    return nlohmann::json::parse(in);
}

/// A car program's statistics: the last line of its log that is a JSON object.
nlohmann::json final_stats(const std::string& log)
{
    std::ifstream in(log);
    std::string stats;
    for (std::string line; std::getline(in, line);) {
        if (!line.empty() && line[0] == '{') stats = line;
    }
    return stats.empty() ? nlohmann::json() : nlohmann::json::parse(stats);
}

/// The page as headless Chromium (Debian's) leaves it after loading, scripts run; no request
/// can leave the host (every name unresolvable, every proxy dead).
std::string rendered_dom(const std::string& file)
{
    Process chromium({"/usr/bin/chromium", "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking",
                      "--disable-component-update", "--disable-sync", "--disable-default-apps", "--disable-extensions",
                      "--host-resolver-rules=MAP * ~NOTFOUND", "--proxy-server=127.0.0.1:9", "--virtual-time-budget=5000", "--dump-dom",
                      "file://" + file});
    EXPECT_EQ(chromium.wait(60s), 0) << chromium.errors();
    return chromium.output();
}

/// The parent's pid of process `pid` (0 when it is gone).
int parent_of(int pid)
{
    std::istringstream status(cpm_test::file_text("/proc/" + std::to_string(pid) + "/status"));
    for (std::string line; std::getline(status, line);) {
        if (line.rfind("PPid:", 0) == 0) return std::stoi(line.substr(5));
    }
    return 0;
}

/// A scenario file `name`.yaml in `dir`: car 5 at `start` on map `course` (corridor, gates) with
/// the state machine of the same name, no camera, 5 s of simulated time.
std::string one_car_in_simulated_time(const TempDir& dir, const std::string& name, const std::string& course, const std::string& start,
                                      const std::string& more = "")
{
    const std::string source = cpm_test::source_dir() + "/scenarios/";
    return dir.write(name + ".yaml", "name: " + name + "\ntime: simulated\nduration: 5s\nworld: " + source + "maps/" + course +
                                         ".json\nvehicles:\n  - {id: 5, start: " + start + ", fsm: " + source + "fsm/" + course + ".json}\n" + more);
}

/// The environment entry that marks a run's processes for pid_with.
std::string run_tag(const std::string& out) { return "CPM_TEST_LAB_RUN=" + out; }

}  // namespace

TEST(LabRun, ACorridorRunLeavesItsLogsARecordingThatAnswersAndASummary)
{
    TempDir dir;
    const std::string out = dir.file("run");
    Process run({built_program("cpm"), "lab", "run", kCorridor, "--duration", "8s", "--out", out, "--monitor", "off"});
    ASSERT_EQ(run.wait(90s), 0) << run.output() << run.errors();
    EXPECT_NE(run.output().find("corridor ran: 8.0 s of lab time"), std::string::npos) << run.output();
    for (const char* f : {"cpm_history.log", "sim_5.log", "bridge_5.log", "fsm_5.log", "recording.db", "summary.json", "scenario.yaml"}) {
        EXPECT_TRUE(fs::exists(fs::path(out) / f)) << f;
    }
    const auto summary = summary_of(out);
    EXPECT_EQ(summary["ok"], true) << summary.dump(2);
    EXPECT_EQ(summary["name"], "corridor");
    ASSERT_EQ(summary["processes"].size(), 4u);  // history, simulator, bridge, state machine
    for (const auto& p : summary["processes"]) EXPECT_EQ(p["failed"], false) << p.dump();
    EXPECT_EQ(summary["recording"]["dropped"], 0) << summary.dump(2);

    // The car drove and its state machine ran, and the recording says so through the same
    // questions the live history answers.
    const auto rec = cpm::rtdb::load_recording(out + "/recording.db");
    EXPECT_TRUE(rec.complete) << rec.warning;
    const auto car = rec.store->find("vehicleState", "5");
    ASSERT_TRUE(car) << "the car's states are recorded";
    const auto info = rec.store->info(*car);
    EXPECT_GT(info->samples_total, 300u) << "50 Hz for most of 8 s";
    const auto first = rec.store->range(*car, 0, UINT64_MAX, cpm::rtdb::By::commit, 1).samples;
    const auto last = rec.store->latest(*car);
    ASSERT_FALSE(first.empty());
    ASSERT_TRUE(last.ok());
    // Simulated time: the stamps are lab time from 0, and cover the run's 8 s.
    EXPECT_EQ(summary["time"], "simulated");
    EXPECT_LT(first[0].data_ns, 1'000'000'000u) << "lab time starts at 0";
    EXPECT_GT(double(last.sample.data_ns - first[0].data_ns) * 1e-9, 7.0);
    EXPECT_GT(summary["samples_recorded"].get<uint64_t>(), 300u) << "the history's own count, as the progress line shows it";
    EXPECT_EQ(summary["samples_recorded"], summary["recording"]["written"]) << "one count of the samples recorded";
    // The run's own stop is on the lab's clock like every other sample of a simulated run.
    const auto stop = rec.store->find("stopRequest", "0");
    ASSERT_TRUE(stop) << "the run's stop for every car is recorded";
    const auto stop_sample = rec.store->latest(*stop);
    ASSERT_TRUE(stop_sample.ok());
    EXPECT_GE(stop_sample.sample.data_ns, 7'000'000'000u) << "stamped at the run's end in lab time";
    EXPECT_LE(stop_sample.sample.data_ns, 9'000'000'000u) << "not the wall clock";
    EXPECT_TRUE(rec.store->find("fsmStatus", "5")) << "the state machine's status is recorded";
    // The car's simulator sent a state packet every 20 ms from lab time 0 on, the bridge answered
    // each at its next tick, and the state machine ticked with them (50 a second, not 80).
    const auto sim = final_stats(out + "/sim_5.log");
    const auto bridge = final_stats(out + "/bridge_5.log");
    EXPECT_EQ(sim["state_packets"], 400) << sim.dump();
    EXPECT_EQ(sim["unanswered_states"], 0) << sim.dump();
    EXPECT_EQ(bridge["cycles"], sim["state_packets"]) << bridge.dump();
    const auto fsm_ticks = rec.store->find("readyStatus", cpm::timer_ids::fsm_node(5));
    ASSERT_TRUE(fsm_ticks) << "the state machine's announcements of its ticks are recorded";
    EXPECT_GE(rec.store->info(*fsm_ticks)->samples_total, 400u);
    EXPECT_LE(rec.store->info(*fsm_ticks)->samples_total, 403u) << "one announcement per tick, a first and a last";
    // The lab clock's stop (a SystemTrigger, a type without a Header) is recorded, not skipped.
    const auto trigger = rec.store->find("systemTrigger", "");
    ASSERT_TRUE(trigger) << "the timers' stop is recorded";
    EXPECT_GE(rec.store->info(*trigger)->samples_total, 1u);
    EXPECT_EQ(rec.store->info(*trigger)->data_time, "source_timestamp");
    std::ifstream history_log(out + "/cpm_history.log");
    const std::string history_text((std::istreambuf_iterator<char>(history_log)), std::istreambuf_iterator<char>());
    EXPECT_EQ(history_text.find("too short"), std::string::npos) << history_text;
    std::ifstream fsm_log(out + "/fsm_5.log");
    std::string fsm_text((std::istreambuf_iterator<char>(fsm_log)), std::istreambuf_iterator<char>());
    EXPECT_NE(fsm_text.find("report: driven"), std::string::npos) << "fsm_node was stopped cleanly and printed its report\n" << fsm_text;

    // The report: every plot there and loaded in a real browser, the figures in the summary.
    EXPECT_NE(run.output().find("report: " + out + "/report.html"), std::string::npos) << run.output();
    for (const char* plot : {"map.png", "speed.png", "steering.png", "fsm.png", "clearance.png", "topics.png"}) {
        EXPECT_GT(fs::file_size(fs::path(out) / "plots" / plot), 1000u) << plot;
    }
    const std::string dom = rendered_dom(out + "/report.html");
    EXPECT_NE(dom.find("<body data-images=\"6\" data-images-loaded=\"6\""), std::string::npos) << dom.substr(0, 2000);
    EXPECT_NE(dom.find("<h1>Run corridor</h1>"), std::string::npos);
    EXPECT_NE(dom.find("cpm history --file recording.db"), std::string::npos) << "the report names the file to ask";
    EXPECT_NE(dom.find("vehicleState"), std::string::npos) << "the topics table";
    const auto figures = summary_of(out)["report"];
    EXPECT_GT(figures["cars"]["5"]["driven_m"].get<double>(), 1.0) << figures.dump(2);
    EXPECT_GT(figures["cars"]["5"]["min_clearance_m"].get<double>(), 0.2) << figures.dump(2);
    EXPECT_NEAR(figures["topics"]["vehicleState"]["rate_hz"].get<double>(), 50, 5) << figures.dump(2);
    EXPECT_EQ(figures["topics"]["vehicleState"]["rate_per"], "lab second");
    EXPECT_FALSE(figures["topics"]["vehicleState"].contains("delay_ms_p50")) << "no delay across two clocks";
    EXPECT_TRUE(figures["missed_deadlines"].is_number_unsigned()) << figures.dump(2);

    // Drawn again from the folder alone.
    fs::remove_all(fs::path(out) / "plots");
    Process again({built_program("cpm"), "lab", "report", out});
    ASSERT_EQ(again.wait(60s), 0) << again.errors();
    EXPECT_TRUE(fs::exists(fs::path(out) / "plots" / "map.png"));
    Process nothing({built_program("cpm"), "lab", "report", dir.file("none")});
    EXPECT_EQ(nothing.wait(30s), 1);
    EXPECT_NE(nothing.errors().find("no run folder " + dir.file("none")), std::string::npos) << nothing.errors();

    // Times into the run are lab time in every verb: 8 s of lab time took about a second here.
    const std::string recording = out + "/recording.db";
    Process at({built_program("cpm"), "history", "--file", recording, "at", "--topic", "vehicleState", "--key", "5", "--time", "5s", "--by",
                "data", "--json"});
    ASSERT_EQ(at.wait(30s), 0) << at.errors();
    const auto at_5s = nlohmann::json::parse(at.output())["data_ns"].get<uint64_t>();
    EXPECT_LE(at_5s, 5'000'000'000u);
    EXPECT_GT(at_5s, 4'950'000'000u) << "the car's state at 5 s of lab time";
    Process last_second({built_program("cpm"), "history", "--file", recording, "range", "--topic", "vehicleState", "--key", "5", "--from", "-1s",
                  "--to", "now", "--by", "data", "--json"});
    ASSERT_EQ(last_second.wait(30s), 0) << "the last second of lab time, not of the wall clock\n" << last_second.errors();
    const std::string last_out = last_second.output();
    EXPECT_GE(std::count(last_out.begin(), last_out.end(), '\n'), 45) << "50 Hz";
    Process play({built_program("cpm"), "play", recording, "--from", "2s", "--to", "4s", "--topics", "vehicleState", "--wait-for-readers", "0s"});
    ASSERT_EQ(play.wait(60s), 0) << play.errors();
    const auto played = nlohmann::json::parse(play.output())["published"].get<int>();
    EXPECT_NEAR(played, 100, 5) << "2 s of lab time at 50 Hz";
    Process beyond({built_program("cpm"), "play", recording, "--from", "50s", "--wait-for-readers", "0s"});
    EXPECT_EQ(beyond.wait(60s), 1) << "a span with nothing in it is said";
    EXPECT_NE(beyond.errors().find("nothing of " + recording + " lies in the span asked for (--from 50s; its lab clock runs from 0 to 8.0 s)"),
              std::string::npos)
        << beyond.errors();

    // The run as MCAP, for Foxglove: the format's reference reader reads every message as cpm
    // decodes it; the scenario and summary go with it; cpm answers and plays it as the SQLite file.
    const std::string mcap = dir.file("corridor.mcap");
    Process to_mcap({built_program("cpm"), "history", "--file", recording, "export", "--mcap", mcap});
    ASSERT_EQ(to_mcap.wait(60s), 0) << to_mcap.errors();
    EXPECT_EQ(cpm_test::mcap_differences(mcap), "");
    const auto file = cpm::rtdb::mcap::read(mcap);
    const auto run_meta = std::find_if(file.metadata.begin(), file.metadata.end(), [](const auto& m) { return m.name == "cpm.run"; });
    ASSERT_NE(run_meta, file.metadata.end());
    EXPECT_EQ(run_meta->values.at("scenario"), cpm_test::file_text(out + "/scenario.yaml"));
    EXPECT_EQ(nlohmann::json::parse(run_meta->values.at("summary"))["name"], "corridor");
    Process at_mcap({built_program("cpm"), "history", "--file", mcap, "at", "--topic", "vehicleState", "--key", "5", "--time", "5s", "--by", "data",
                     "--json"});
    ASSERT_EQ(at_mcap.wait(30s), 0) << at_mcap.errors();
    EXPECT_EQ(at_mcap.output(), at.output());
    Process play_mcap({built_program("cpm"), "play", mcap, "--from", "2s", "--to", "4s", "--topics", "vehicleState", "--wait-for-readers", "0s"});
    ASSERT_EQ(play_mcap.wait(60s), 0) << play_mcap.errors();
    EXPECT_EQ(nlohmann::json::parse(play_mcap.output())["published"].get<int>(), played);

    // For Foxglove's 3D panel: each pose also as a FrameTransform on /tf, car_5 (the true pose)
    // and car_5_estimate (the car's own) in map, as the reference reader decodes them; a view
    // for viewers only, not a topic of the run.
    const std::string three_d = dir.file("corridor_3d.mcap");
    Process to_3d({built_program("cpm"), "history", "--file", recording, "export", "--mcap", three_d, "--foxglove-3d"});
    ASSERT_EQ(to_3d.wait(60s), 0) << to_3d.errors();
    EXPECT_EQ(cpm_test::mcap_differences(three_d), "");
    std::string refused;
    const auto read = cpm_test::mcap_reference_read(three_d, refused);
    ASSERT_EQ(refused, "");
    std::map<std::string, nlohmann::json> first_frame;  // by frame
    size_t frames = 0;
    for (const auto& m : read) {
        if (m.value("topic", "") != "/tf") continue;
        ++frames;
        EXPECT_EQ(m["data"]["parent_frame_id"], "map");
        first_frame.emplace(m["data"]["child_frame_id"].get<std::string>(), m);
    }
    EXPECT_EQ(frames, info->samples_total + rec.store->info(*rec.store->find("vehicleObservation", "5"))->samples_total);
    ASSERT_TRUE(first_frame.count("car_5") && first_frame.count("car_5_estimate"));
    Process first_pose({built_program("cpm"), "history", "--file", recording, "range", "--topic", "vehicleObservation", "--key", "5", "--from", "0",
                        "--to", "9000000000000000000", "--limit", "1", "--json"});
    ASSERT_EQ(first_pose.wait(30s), 0) << first_pose.errors();
    const auto pose = nlohmann::json::parse(first_pose.output().substr(0, first_pose.output().find('\n')));
    const auto& tf = first_frame["car_5"]["data"];
    EXPECT_DOUBLE_EQ(tf["translation"]["x"].get<double>(), pose["data"]["pose"]["x"].get<double>());
    EXPECT_DOUBLE_EQ(tf["translation"]["y"].get<double>(), pose["data"]["pose"]["y"].get<double>());
    EXPECT_NEAR(2 * std::atan2(tf["rotation"]["z"].get<double>(), tf["rotation"]["w"].get<double>()), pose["data"]["pose"]["yaw"].get<double>(), 1e-12);
    EXPECT_EQ(first_frame["car_5"]["publish_time"], std::to_string(pose["data_ns"].get<uint64_t>()));
    Process listed({built_program("cpm"), "history", "--file", three_d, "list"});
    ASSERT_EQ(listed.wait(30s), 0) << listed.errors();
    EXPECT_EQ(listed.output().find("/tf"), std::string::npos) << listed.output();
}

TEST(LabRun, ANodeKilledMidRunIsNamedWithTheEndOfItsLog)
{
    TempDir dir;
    const std::string out = dir.file("run");
    // Real time: in simulated time the corridor's 60 s pass in about 4 s, before the test acts.
    Process run({built_program("cpm"), "lab", "run", kCorridor, "--time", "real", "--duration", "60s", "--out", out, "--monitor", "off"},
                {run_tag(out)});
    const std::string fsm_args = "--vehicle_id 5 --fsm " + fs::weakly_canonical(cpm_test::source_dir() + "/scenarios/fsm/corridor.json").string();
    int pid = 0;
    ASSERT_TRUE(cpm_test::wait_until([&] { return (pid = pid_with(fsm_args, run_tag(out))) != 0 && fs::exists(out + "/fsm_5.log"); }, 30s)) << run.errors();
    // Running, and saying so in its log (on a loaded machine that can take longer than a moment);
    // its machine ends by itself some 20 s into the run, the node with it.
    EXPECT_TRUE(cpm_test::wait_until([&] { return cpm_test::file_text(out + "/fsm_5.log").find("fsm_node: vehicle 5 runs") != std::string::npos; }, 15s))
        << cpm_test::file_text(out + "/fsm_5.log");
    // The run's own child, and the signal taken: else the test, not the run, is at fault.
    EXPECT_EQ(parent_of(pid), run.pid()) << "pid " << pid << ": " << cpm_test::file_text("/proc/" + std::to_string(pid) + "/status");
    ASSERT_EQ(::kill(pid, SIGKILL), 0) << "pid " << pid << ": " << std::strerror(errno);
    EXPECT_EQ(run.wait(60s), 1) << run.output() << run.errors();
    EXPECT_NE(run.errors().find("fsm_5 killed by SIGKILL during the run"), std::string::npos) << run.errors();
    EXPECT_NE(run.errors().find("fsm_node: vehicle 5"), std::string::npos) << "the end of its log is shown\n" << run.errors();
    {
        std::ifstream log(out + "/fsm_5.log");
        std::string line, last;
        while (std::getline(log, line)) {
            if (!line.empty()) last = line;
        }
        ASSERT_FALSE(last.empty());
        const std::string said = run.errors();
        size_t times = 0;
        for (auto at = said.find(last); at != std::string::npos; at = said.find(last, at + 1)) ++times;
        EXPECT_EQ(times, 1u) << "the end of its log is shown once\n" << said;
    }
    const auto summary = summary_of(out);
    EXPECT_EQ(summary["ok"], false);
    EXPECT_NE(summary["error"].get<std::string>().find("fsm_5"), std::string::npos);
    EXPECT_EQ(pid_with(out + "/recording.db", run_tag(out)), 0) << "every process of the run is stopped";
    EXPECT_EQ(pid_with("--map " + fs::weakly_canonical(cpm_test::source_dir() + "/scenarios/maps/corridor.json").string() + " --start", run_tag(out)), 0);
}

TEST(LabRun, ANodeWithRestartTrueIsStartedAgainAndEveryNodeGetsTheScenariosQos)
{
    TempDir dir;
    const std::string out = dir.file("run");
    const std::string source = cpm_test::source_dir() + "/scenarios/";
    // vehicleState is best effort unless a scenario says otherwise. Real time: in simulated time
    // a quick machine drove the whole corridor (its machine ends, exit 0) before the kill came.
    const std::string file = dir.write("restart.yaml", "name: restart\ntime: real\nduration: 12s\nworld: " + source +
                                                           "maps/corridor.json\nvehicles:\n  - id: 5\n    start: [0.0, -0.01, 0.0]\n"
                                                           "    fsm: " + source + "fsm/corridor.json\n    restart: true\n"
                                                           "qos: {vehicleState: {reliable: true, history_depth: 2}}\n");
    Process run({built_program("cpm"), "lab", "run", file, "--out", out, "--monitor", "off"}, {run_tag(out)});
    const std::string fsm_args = "--vehicle_id 5 --fsm " + fs::weakly_canonical(source + "fsm/corridor.json").string();
    int pid = 0;
    ASSERT_TRUE(cpm_test::wait_until([&] { return (pid = pid_with(fsm_args, run_tag(out))) != 0 && fs::exists(out + "/fsm_5.log"); }, 30s)) << run.errors();

    // Every writer and reader of vehicleState on the run's domain is reliable now (asked again
    // until the car's writer and a reader are seen: a slow build may not have them all yet).
    nlohmann::json topic;
    ASSERT_TRUE(cpm_test::wait_until([&] {
        Process info({built_program("cpm"), "topic", "info", "vehicleState", "--json"});
        if (info.wait(30s) != 0) return false;
        topic = nlohmann::json::parse(info.output(), nullptr, false);
        return topic.is_object() && !topic["writers"].empty() && !topic["readers"].empty();
    }, 60s, 200ms)) << topic.dump(2);
    for (const auto* side : {"writers", "readers"}) {
        for (const auto& e : topic[side]) {
            if (e["participant"] == "cpm_history" || e["participant"] == "cpm_topic") continue;  // they take what the writers offer
            EXPECT_EQ(e["reliability"], "reliable") << side << ": " << e.dump();
        }
    }

    ::kill(pid, SIGKILL);
    EXPECT_EQ(run.wait(120s), 0) << run.output() << run.errors();
    EXPECT_NE(run.errors().find("fsm_5 killed by SIGKILL; restarting it (restart: true)"), std::string::npos) << run.errors();
    std::ifstream log(out + "/fsm_5.log");
    const std::string text((std::istreambuf_iterator<char>(log)), std::istreambuf_iterator<char>());
    EXPECT_NE(text.find("--- restarted ---"), std::string::npos) << "the second life's output follows the first's";
    const auto summary = summary_of(out);
    EXPECT_EQ(summary["ok"], true) << summary.dump(2);
    EXPECT_EQ(summary["qos"]["vehicleState"]["reliable"], true);
    bool found = false;
    for (const auto& p : summary["processes"]) {
        if (p["name"] != "fsm_5") continue;
        found = true;
        EXPECT_EQ(p["restarts"], 1) << p.dump();
        EXPECT_EQ(p["failed"], false) << p.dump();
    }
    EXPECT_TRUE(found);
}

TEST(LabRun, ADomainInUseIsRefusedBeforeAnythingStarts)
{
    TempDir dir;
    // Somebody else on the run's domain: a parameter server (any participant would do).
    dir.write("p.json", "{\"a\": 1}");
    Process other({built_program("cpm"), "param", "serve", dir.file("p.json")});
    ASSERT_TRUE(cpm_test::wait_until([&] { return other.output().find("serving") != std::string::npos; }, 30s)) << other.errors();
    Process run({built_program("cpm"), "lab", "run", kCorridor, "--out", dir.file("run"), "--monitor", "off"});
    EXPECT_EQ(run.wait(60s), 1) << run.output();
    EXPECT_NE(run.errors().find("nothing started"), std::string::npos) << run.errors();
    EXPECT_NE(run.errors().find("is in use by 1 participant(s): cpm"), std::string::npos) << run.errors();
    EXPECT_FALSE(fs::exists(dir.file("run"))) << "no run folder";
    other.kill(SIGINT);
    EXPECT_EQ(other.wait(30s), 0);
}

TEST(LabRun, AMonitorPortInUseIsRefusedBeforeAnythingStarts)
{
    TempDir dir;
    const cpm_test::HeldTcpPort taken;  // something else listens on the port the monitor wants
    Process run({built_program("cpm"), "lab", "run", kCorridor, "--out", dir.file("run"), "--monitor", std::to_string(taken.port())});
    EXPECT_EQ(run.wait(60s), 1) << run.output();
    EXPECT_NE(run.errors().find("nothing started"), std::string::npos) << run.errors();
    EXPECT_NE(run.errors().find("corridor.yaml: monitor: tcp:" + std::to_string(taken.port()) +
                                " cannot be taken on this host (Address already in use): choose another port"),
              std::string::npos)
        << run.errors();
    EXPECT_FALSE(fs::exists(dir.file("run"))) << "no run folder";
}

TEST(LabRun, CtrlCStopsEverythingAndLeavesAReadableRecording)
{
    TempDir dir;
    const std::string out = dir.file("run");
    // Real time: in simulated time the corridor's 60 s pass in about 4 s, before the test acts.
    Process run({built_program("cpm"), "lab", "run", kCorridor, "--time", "real", "--duration", "60s", "--out", out, "--monitor", "off"},
                {run_tag(out)});
    ASSERT_TRUE(cpm_test::wait_until([&] { return run.errors().find("processes on domain") != std::string::npos; }, 30s)) << run.errors();
    std::this_thread::sleep_for(4s);
    run.kill(SIGINT);
    EXPECT_EQ(run.wait(60s), 1) << run.output() << run.errors();
    EXPECT_NE(run.output().find("corridor was stopped"), std::string::npos) << run.output();
    const auto rec = cpm::rtdb::load_recording(out + "/recording.db");
    EXPECT_TRUE(rec.complete) << rec.warning;
    const auto car = rec.store->find("vehicleState", "5");
    ASSERT_TRUE(car);
#ifdef CPM_TEST_SANITIZED
    const size_t at_least = 20;  // a car 5-15 times slower under a sanitizer (77 seen there)
#else
    const size_t at_least = 100;  // 4 s at 50 Hz, less the start
#endif
    EXPECT_GT(rec.store->info(*car)->samples_total, at_least);
    EXPECT_EQ(summary_of(out)["interrupted"], true);
}

TEST(LabRun, CtrlCInSimulatedTimeSaysHowMuchLabTimeRanAndWhyTheRunEndedEarly)
{
    TempDir dir;
    const std::string out = dir.file("run");
    Process run({built_program("cpm"), "lab", "run", kCorridor, "--duration", "1000s", "--out", out, "--monitor", "off"});
    ASSERT_TRUE(cpm_test::wait_until([&] { return run.errors().find("processes on domain") != std::string::npos; }, 30s)) << run.errors();
    std::this_thread::sleep_for(3s);
    run.kill(SIGINT);
    EXPECT_EQ(run.wait(60s), 1) << run.output() << run.errors();
    const auto summary = summary_of(out);
    EXPECT_EQ(summary["interrupted"], true);
    EXPECT_GT(summary["lab_time_s"].get<double>(), 0.5) << "the lab clock ran for 3 s of real time\n" << summary.dump(2);
    EXPECT_LT(summary["lab_time_s"].get<double>(), 1000.0);
    const std::regex said("corridor was stopped: ([0-9.]+) s of lab time");
    std::smatch m;
    const std::string output = run.output();
    ASSERT_TRUE(std::regex_search(output, m, said)) << output;
    EXPECT_GT(std::stod(m[1]), 0.5) << output;
    std::ifstream page(out + "/report.html");
    const std::string html((std::istreambuf_iterator<char>(page)), std::istreambuf_iterator<char>());
    EXPECT_NE(html.find("did not end well: it was stopped (Ctrl-C or SIGTERM) before its end"), std::string::npos) << html.substr(0, 3000);
}

TEST(LabRun, ADashCamSaveInSimulatedTimeHoldsTheLabTimeSpanInTheRunFolder)
{
    TempDir dir;
    const std::string out = dir.file("run");
    Process run({built_program("cpm"), "lab", "run", kCorridor, "--duration", "1000s", "--out", out, "--monitor", "off"});
    ASSERT_TRUE(cpm_test::wait_until([&] { return run.errors().find("processes on domain") != std::string::npos; }, 30s)) << run.errors();
    std::this_thread::sleep_for(3s);  // some seconds of lab time
    // The cars stamp lab time from 0: the span is on that clock, not on the wall clock.
    Process save({built_program("cpm"), "history", "save", "dash.db", "--before", "2s", "--after", "0s", "--topics", "vehicleState", "--json"});
    ASSERT_EQ(save.wait(60s), 0) << save.errors() << save.output();
    run.kill(SIGINT);
    EXPECT_EQ(run.wait(60s), 1) << run.errors();
    const auto saved = nlohmann::json::parse(save.output());
    EXPECT_EQ(saved["file"], out + "/dash.db") << "in the run's folder";
    EXPECT_LT(saved["to_ns"].get<uint64_t>(), 1000'000'000'000ull) << "lab time: " << saved.dump();
    EXPECT_EQ(saved["to_ns"].get<uint64_t>() - saved["from_ns"].get<uint64_t>(), 2'000'000'000u);
    Process states({built_program("cpm"), "history", "--file", out + "/dash.db", "range", "--topic", "vehicleState", "--key", "5", "--from", "0",
                    "--to", "9000000000000000000", "--by", "data", "--json"});
    ASSERT_EQ(states.wait(30s), 0) << states.errors();
    const std::string lines = states.output();
    EXPECT_NEAR(double(std::count(lines.begin(), lines.end(), '\n')), 100, 3) << "two seconds of lab time at 50 Hz";
    // The run's folder still reads as the run.
    Process whole({built_program("cpm"), "history", "--file", out, "latest", "--topic", "vehicleState", "--key", "5", "--json"});
    ASSERT_EQ(whole.wait(30s), 0) << whole.errors();
    EXPECT_GE(nlohmann::json::parse(whole.output())["data_ns"].get<uint64_t>(), saved["to_ns"].get<uint64_t>() - 100'000'000);
}

TEST(LabRun, ANodeTheSimulatedClockWaitsForInVainIsNamedWithTheEndOfItsLog)
{
    // A state machine frozen (SIGSTOP) before it joins the simulated clock: the clock waits for
    // it in vain (the scenario's timeouts.start), and the run names it with the end of its log.
    TempDir dir;
    const std::string file = one_car_in_simulated_time(dir, "frozen", "corridor", "[0.0, -0.01, 0.0]", "timeouts: {start: 10s}\n");
    const std::string out = dir.file("run");
    Process run({built_program("cpm"), "lab", "run", file, "--out", out, "--monitor", "off"}, {run_tag(out)});
    int pid = 0;
    ASSERT_TRUE(cpm_test::wait_until([&] { return (pid = pid_with("/bin/fsm_node ", run_tag(out))) != 0; }, 30s, 1ms)) << run.errors();
    ::kill(pid, SIGSTOP);  // it waits for its car's first state before it announces its timer: stopped well before
    EXPECT_EQ(run.wait(90s), 1) << run.output() << run.errors();
    const std::string said = run.output() + run.errors();
    EXPECT_NE(said.find("simulated time not started within 10000 ms: no announcement from 'fsm_node_5'"), std::string::npos) << said;
    EXPECT_NE(said.find("fsm_5's log (" + out + "/fsm_5.log) ends:"), std::string::npos) << said;
    EXPECT_EQ(pid_with("/bin/fsm_node ", run_tag(out)), 0) << "the frozen node is stopped with the run";
}

TEST(LabRun, InRealTimeACarThatNeverSendsAStateIsNamedWithItsProcessesLogs)
{
    // Lab time in real time starts with every car's first state: the car's simulator frozen
    // (SIGSTOP) before its first packet, the run waits, says for what, and after the scenario's
    // timeouts.start ends naming the car and its processes. Never a run whose time ran without its car.
    TempDir dir;
    const std::string source = cpm_test::source_dir() + "/scenarios/";
    const std::string file = dir.write("silent.yaml", "name: silent\ntime: real\nduration: 10s\nworld: " + source +
                                                          "maps/corridor.json\nvehicles:\n  - {id: 5, start: [0.0, -0.01, 0.0]}\n"
                                                          "timeouts: {start: 15s}\n");  // past the second progress line (10 s)
    const std::string out = dir.file("run");
    Process run({built_program("cpm"), "lab", "run", file, "--out", out, "--monitor", "off"}, {run_tag(out)});
    int pid = 0;
    ASSERT_TRUE(cpm_test::wait_until([&] { return (pid = pid_with("/bin/firmware_sim ", run_tag(out))) != 0; }, 30s, 1ms)) << run.errors();
    ASSERT_EQ(::kill(pid, SIGSTOP), 0);
    EXPECT_EQ(run.wait(90s), 1) << run.output() << run.errors();
    const std::string said = run.output() + run.errors();
    EXPECT_NE(said.find("lab time 0.0 / 10.0 s (waiting for car 5's first state)"), std::string::npos) << said;
    EXPECT_NE(said.find("the lab clock could not start: no state within 15000 ms from car 5 ('sim_5', 'bridge_5')"), std::string::npos) << said;
    EXPECT_NE(said.find("sim_5's log (" + out + "/sim_5.log) ends:"), std::string::npos) << said;
    EXPECT_NE(said.find("bridge_5's log (" + out + "/bridge_5.log) ends:"), std::string::npos) << said;
    EXPECT_EQ(said.find("lab time starts"), std::string::npos) << said;
    const auto summary = summary_of(out);
    EXPECT_EQ(summary["lab_time_s"], 0.0) << "no lab time ran without the car: " << summary.dump(2);
    EXPECT_EQ(pid_with("/bin/firmware_sim ", run_tag(out)), 0) << "the frozen simulator is stopped with the run";
}

TEST(LabRun, AMachineThatLooksForGatesOnACarWithoutACameraIsRefusedBeforeAnythingStarts)
{
    TempDir dir;
    const std::string file = one_car_in_simulated_time(dir, "no_camera", "gates", "[0.0, 0.0, 0.3]");
    Process run({built_program("cpm"), "lab", "run", file, "--out", dir.file("run"), "--monitor", "off"});
    EXPECT_EQ(run.wait(60s), 1) << run.output() << run.errors();
    EXPECT_NE(run.errors().find("nothing started"), std::string::npos) << run.errors();
    EXPECT_NE(run.errors().find("vehicles[0].fsm: its machine works on ArUco markers, but the car has no camera"), std::string::npos) << run.errors();
    EXPECT_FALSE(fs::exists(dir.file("run")));
}

TEST(LabRun, AWrongScenarioStartsNothing)
{
    TempDir dir;
    const std::string bad = dir.write("bad.yaml", "name: bad\nduration: forever\nworld: nowhere.json\nvehicles: [{id: 1}, {id: 1}]\n");
    Process run({built_program("cpm"), "lab", "run", bad, "--out", dir.file("run"), "--monitor", "off"});
    EXPECT_EQ(run.wait(30s), 1);
    EXPECT_NE(run.errors().find("3 error(s), nothing started"), std::string::npos) << run.errors();
    EXPECT_NE(run.errors().find(bad + ":2: duration: 'forever' is not a duration"), std::string::npos) << run.errors();
    EXPECT_NE(run.errors().find("vehicles[1].id: 1 is given twice"), std::string::npos) << run.errors();
    EXPECT_FALSE(fs::exists(dir.file("run"))) << "no run folder";
    Process flag({built_program("cpm"), "lab", "run", kCorridor, "--time", "sometimes"});
    EXPECT_EQ(flag.wait(30s), 2);
    EXPECT_NE(flag.errors().find("--time 'sometimes'"), std::string::npos) << flag.errors();
}

TEST(LabRun, RoutingInRealTimeRunsItsWholeDurationFromTheCommonStart)
{
    // Real time with routing starts the clock a second ahead; the run then lasts its duration
    // from that start (once ended at once: two clock reads in one expression underflowed).
    TempDir dir;
    const std::string out = dir.file("run");
    Process run({built_program("cpm"), "lab", "run", cpm_test::source_dir() + "/scenarios/labs/intersection.yaml", "--time", "real",
                 "--duration", "3s", "--out", out, "--monitor", "off"});
    ASSERT_EQ(run.wait(90s), 0) << run.output() << run.errors();
    const auto summary = summary_of(out);
    EXPECT_EQ(summary["time"], "real");
    EXPECT_NEAR(summary["lab_time_s"].get<double>(), 3.0, 0.05) << summary.dump(2);
    EXPECT_GE(summary["real_s"].get<double>(), 3.0) << "3 s of real time take at least 3 s";
    std::ifstream log(out + "/central_routing.log");
    const std::string text((std::istreambuf_iterator<char>(log)), std::istreambuf_iterator<char>());
    EXPECT_EQ(text.find("\"cycles\":0,"), std::string::npos) << "the planner ran\n" << text;
}

TEST(LabRun, ASecuredLabRunsEachProcessAsItsOwnNodeAndAStrangerSeesNothing)
{
    TempDir dir;
    const std::string lab = dir.file("lab-sec");
    Process init({built_program("cpm"), "security", "init", lab, "--days", "30"});
    ASSERT_EQ(init.wait(60s), 0) << init.errors();
    const std::string source = cpm_test::source_dir() + "/scenarios/";
    // In real time, long enough that the looks below happen while it runs (checked).
    const std::string file = dir.write("secured.yaml", "name: secured\ntime: real\nduration: 12s\nworld: " + source +
                                                           "maps/corridor.json\nvehicles:\n  - id: 5\n    start: [0.0, -0.01, 0.0]\n"
                                                           "    fsm: " + source + "fsm/corridor.json\nsecurity: " + lab + "\n");
    const std::string out = dir.file("run");
    Process run({built_program("cpm"), "lab", "run", file, "--out", out, "--monitor", "off"});
    ASSERT_TRUE(cpm_test::wait_until([&] { return fs::exists(out + "/fsm_5.log") || run.wait(0ms) != -1; }, 60s)) << run.errors();
    // A participant without the lab's credentials on the run's domain sees no topic at all;
    // the same look with a node of the lab (the history's, allowed every topic) sees the car.
    ASSERT_TRUE(cpm_test::wait_until([&] { return fs::exists(lab + "/nodes/run-cpm_history/permissions.p7s"); }, 30s));
    Process stranger({built_program("cpm"), "topic", "list"});
    ASSERT_EQ(stranger.wait(30s), 0) << stranger.errors();
    Process member({built_program("cpm"), "topic", "list", "--security", lab + "/nodes/run-cpm_history"});
    ASSERT_EQ(member.wait(30s), 0) << member.errors();
    EXPECT_EQ(run.wait(0ms), -1) << "the run had ended before the looks: they prove nothing";
    EXPECT_EQ(stranger.output().find("vehicleState"), std::string::npos) << stranger.output();
    EXPECT_NE(member.output().find("vehicleState"), std::string::npos) << "the positive control: the lab's own node sees the car\n"
                                                                       << member.output() << member.errors();
    EXPECT_EQ(run.wait(120s), 0) << run.output() << run.errors();

    // Every process ran as a node of its own, issued by the run, and the secured history
    // recorded the car.
    for (const char* node : {"run-cpm_lab_run", "run-cpm_history", "run-sim_5", "run-bridge_5", "run-fsm_5"})
        EXPECT_TRUE(fs::exists(fs::path(lab) / "nodes" / node / "permissions.p7s")) << node;
    const auto summary = summary_of(out);
    EXPECT_EQ(summary["ok"], true) << summary.dump(2);
    Process latest({built_program("cpm"), "history", "--file", out + "/recording.db", "latest", "--topic", "vehicleState", "--key", "5"});
    EXPECT_EQ(latest.wait(30s), 0) << latest.output() << latest.errors();
    for (const auto& p : summary["processes"]) {
        const auto argv = p["argv"].get<std::vector<std::string>>();
        const auto flag = std::find(argv.begin(), argv.end(), "--security");
        ASSERT_NE(flag, argv.end()) << p.dump();
        EXPECT_EQ(*(flag + 1), lab + "/nodes/run-" + p["name"].get<std::string>()) << p.dump();
    }
}

TEST(LabRun, ANodeThatStallsMidRunIsNamedWhenTheSimulatedClockGivesUpOnIt)
{
    // The car's simulator frozen (SIGSTOP) while the simulated clock steps (the state machine is
    // done after 20 s of lab time, about a second here): the clock waits its step timeout (the
    // scenario's timeouts.step) for the node's next tick, then the run ends naming it. Never a
    // silent hang.
    TempDir dir;
    const std::string source = cpm_test::source_dir() + "/scenarios/";
    const std::string file = dir.write("stall.yaml", "name: stall\ntime: simulated\nduration: 3600s\nworld: " + source +
                                                         "maps/corridor.json\nvehicles:\n  - {id: 5, start: [0.0, -0.01, 0.0], fsm: " + source +
                                                         "fsm/corridor.json}\ntimeouts: {step: 3s}\n");
    const std::string out = dir.file("run");
    Process run({built_program("cpm"), "lab", "run", file, "--out", out, "--monitor", "off"}, {run_tag(out)});
    int pid = 0;
    ASSERT_TRUE(cpm_test::wait_until([&] { return (pid = pid_with("/bin/firmware_sim ", run_tag(out))) != 0; }, 30s, 1ms)) << run.errors();
    // Lab time moves: the run says so about once a second.
    ASSERT_TRUE(cpm_test::wait_until([&] { return (run.output() + run.errors()).find("(simulated, ") != std::string::npos; }, 30s))
        << run.output() << run.errors();
    ASSERT_EQ(::kill(pid, SIGSTOP), 0);
    EXPECT_EQ(run.wait(90s), 1) << run.output() << run.errors();
    const std::string said = run.output() + run.errors();
    EXPECT_NE(said.find("simulated time stuck at "), std::string::npos) << said;
    EXPECT_EQ(said.find("simulated time stuck at 0 ns"), std::string::npos) << "it stalled mid-run, not at the start:\n" << said;
    EXPECT_NE(said.find("no announcement from 'firmware_sim_5' within 3000 ms"), std::string::npos) << said;
    EXPECT_NE(said.find("sim_5's log (" + out + "/sim_5.log) ends:"), std::string::npos) << said;
    EXPECT_EQ(pid_with("/bin/firmware_sim ", run_tag(out)), 0) << "the frozen node is stopped with the run";
}

TEST(LabRun, TheCorridorOnTheCarsAvrFirmwareInSimulatedTimeEndsInItsStopState)
{
    // firmware: avr - the ELF a car is flashed with, in simavr on the lab's simulated clock, the
    // same bridge and state machine as with firmware_sim: the whole corridor to its Stop state.
    TempDir dir;
    const std::string source = cpm_test::source_dir() + "/scenarios/";
    const std::string scenario =
        dir.write("corridor_avr.yaml", "name: corridor_avr\ntime: simulated\nduration: 40s\nworld: " + source +
                                           "maps/corridor.json\nvehicles:\n  - {id: 5, start: [0.0, -0.01, 0.0], firmware: avr, fsm: " +
                                           source + "fsm/corridor.json}\n");
    const std::string out = dir.file("run");
    Process run({built_program("cpm"), "lab", "run", scenario, "--out", out, "--monitor", "off"});
    ASSERT_EQ(run.wait(120s), 0) << run.output() << run.errors();
    const auto summary = summary_of(out);
    EXPECT_EQ(summary["ok"], true) << summary.dump(2);
    std::ifstream fsm_log(out + "/fsm_5.log");
    const std::string fsm_text((std::istreambuf_iterator<char>(fsm_log)), std::istreambuf_iterator<char>());
    EXPECT_NE(fsm_text.find("ended in state 3 (Stop)"), std::string::npos) << fsm_text;
    const auto j = final_stats(out + "/sim_5.log");
    ASSERT_TRUE(j.is_object()) << "firmware_hil's statistics at its end";
    const std::string stats = j.dump();
    // One state packet per 20 ms of the chip's 40 s, every one answered in time.
    EXPECT_GE(j["state_packets"].get<int>(), 1990) << stats;
    EXPECT_EQ(j["watchdog_stops"], 0) << stats;
    EXPECT_EQ(j["wall_collisions"], 0) << stats;
    EXPECT_GT(summary["report"]["cars"]["5"]["driven_m"].get<double>(), 10.0) << summary.dump(2);
}
