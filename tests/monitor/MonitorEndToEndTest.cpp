// cpm monitor in a real browser (Debian's chromium, headless, driven over the DevTools protocol):
// a lab run of four simulated cars with fsm_nodes starts its monitor (monitor: in the scenario);
// the page draws four cars where vehicleObservation says they are, /api/state carries the DDS
// samples, the stop buttons stop a car and then every car; a monitor without --allow-stop
// refuses; during `cpm play` of the recording the page says it is a replay.
#include <cpm/AsyncReader.hpp>
#include <cpm/Participant.hpp>
#include <cpm/topics.hpp>

#include <cpm_test/Browser.hpp>
#include <cpm_test/Isolation.hpp>
#include <cpm_test/Process.hpp>
#include <cpm_test/TempDir.hpp>
#include <cpm_test/SourceDir.hpp>

#include <gtest/gtest.h>
#include <httplib.h>

#include <arpa/inet.h>
#include <csignal>
#include <filesystem>
#include <map>
#include <mutex>
#include <netinet/in.h>
#include <regex>
#include <sys/socket.h>
#include <unistd.h>

using namespace std::chrono_literals;
using cpm_test::built_program;
using cpm_test::Process;
using cpm_test::TempDir;
using cpm_test::wait_until;
namespace fs = std::filesystem;
namespace t = cpm::topics;

namespace {

#ifdef CPM_TEST_SANITIZED
constexpr auto kStateWait = std::chrono::seconds(15);  // every process 5-15 times slower
#else
constexpr auto kStateWait = std::chrono::seconds(5);
#endif

/// What the test itself reads off the domain: every car's samples of the last seconds, by stamp.
struct LabView
{
    std::mutex mutex;
    std::map<int, std::map<uint64_t, VehicleState>> states;
    std::map<int, std::map<uint64_t, VehicleObservation>> seen;
    cpm::Participant participant{cpm::ParticipantOptions::from_init()};
    cpm::AsyncReader<VehicleState> state_reader{[this](std::vector<VehicleState>& b) { keep(states, b); }, participant, t::vehicle_state.name,
                                                t::vehicle_state.reader};
    cpm::AsyncReader<VehicleObservation> seen_reader{[this](std::vector<VehicleObservation>& b) { keep(seen, b); }, participant,
                                                     t::vehicle_observation.name, t::vehicle_observation.reader};

    template <class T>
    void keep(std::map<int, std::map<uint64_t, T>>& by_car, std::vector<T>& batch)
    {
        std::lock_guard lock(mutex);
        for (auto& s : batch) {
            auto& mine = by_car[s.vehicle_id()];
            mine[s.header().create_stamp().nanoseconds()] = s;
            while (mine.size() > 500) mine.erase(mine.begin());
        }
    }
    double speed(int id)
    {
        std::lock_guard lock(mutex);
        return states[id].empty() ? -1 : states[id].rbegin()->second.speed();
    }
};

nlohmann::json api_state(int port)
{
    httplib::Client http("127.0.0.1", port);
    auto r = http.Get("/api/state");
    return r && r->status == 200 ? nlohmann::json::parse(r->body) : nlohmann::json();
}

/// Four cars, each with its own state, seen from outside, and its state machine's state.
bool four_cars_running(const nlohmann::json& state)
{
    if (!state.is_object() || !state.contains("vehicles") || state["vehicles"].size() != 4) return false;
    for (const auto& v : state["vehicles"]) {
        if (!v.contains("state_stamp_ns") || v.value("pose_from", "") != "vehicleObservation" || !v.contains("fsm_state") || v["fsm_state"].is_null())
            return false;
    }
    return true;
}

/// The cars as the page drew them: the screen point of each car's reference point, turned back
/// into world metres through the map's own transform.
const char* kDrawnCars = R"(
  [...document.querySelectorAll('#cars .car')].map(g => {
    const screen = new DOMPoint(0, 0).matrixTransform(g.getScreenCTM());
    const world = screen.matrixTransform(document.getElementById('world').getScreenCTM().inverse());
    const map = document.getElementById('map').getBoundingClientRect();
    return {id: +g.dataset.id, x: world.x, y: world.y,
            visible: screen.x >= map.left && screen.x <= map.right && screen.y >= map.top && screen.y <= map.bottom};
  }))";

/// Four cars round the loop (scenarios/labs/loop.yaml's), each on its own side: their machines
/// drive until stopped, so that the stop buttons stop cars that drive however long the page
/// takes to come up on a loaded machine (a corridor's cars had stopped by themselves).
const char* kScenario = R"(name: four
time: real
duration: 90s
world: WORLD
vehicles:
  - {id: 1, start: [1.0, -0.01, 0.0], fsm: FSM}
  - {id: 2, start: [7.41, 1.5, 1.5708], fsm: FSM}
  - {id: 3, start: [5.5, 5.41, 3.1416], fsm: FSM}
  - {id: 4, start: [0.09, 3.5, -1.5708], fsm: FSM}
record: {topics: ["*"]}
monitor: {port: PORT, allow_stop: true}
)";

}  // namespace

TEST(MonitorEndToEnd, FourCarsInTheBrowserMatchTheirSamplesAndTheStopButtonsStopThem)
{
    cpm_test::test_domain_id();
    TempDir dir;
    const int port = cpm_test::free_tcp_port();
    std::string yaml = kScenario;
    yaml = std::regex_replace(yaml, std::regex("WORLD"), cpm_test::source_dir() + "/scenarios/maps/loop.json");
    yaml = std::regex_replace(yaml, std::regex("FSM"), cpm_test::source_dir() + "/scenarios/fsm/loop.json");
    yaml = std::regex_replace(yaml, std::regex("PORT"), std::to_string(port));
    const std::string out = dir.file("run");
    Process run({built_program("cpm"), "lab", "run", dir.write("four.yaml", yaml), "--out", out});
    ASSERT_TRUE(wait_until([&] { return four_cars_running(api_state(port)) || run.errors().find("nothing started") != std::string::npos; },
                           60s, 200ms))
        << "no four cars on the monitor (port " << port << ") within 60 s; it shows:\n"
        << api_state(port).dump() << "\nthe lab run said:\n"
        << run.errors();
    ASSERT_TRUE(four_cars_running(api_state(port))) << "the lab run's monitor shows four cars, each with its state and machine\n"
                                                    << run.errors();
    // The test's own reader joins once the run has claimed its domain (a run refuses a domain
    // with others on it).
    LabView lab;
    ASSERT_TRUE(wait_until(
        [&] {
            std::lock_guard lock(lab.mutex);
            return lab.states.size() == 4 && lab.seen.size() == 4;
        },
        10s, 50ms));
    EXPECT_NE(run.errors().find("watch it live at http://127.0.0.1:" + std::to_string(port) + "/"), std::string::npos) << run.errors();

    // /api/state carries the samples on the domain: each car's speed is that of the VehicleState
    // with the stamp the monitor names, its position that of the VehicleObservation it names.
    {
        // The test's reader gets the same samples, a little later on a slow machine (a sanitizer).
        // One it lost (best effort, a busy machine) is no fault of the monitor's: then a newer
        // view of the monitor's, whose samples the test has, within 10 s.
        nlohmann::json state;
        const auto test_has_its_samples = [&] {
            std::lock_guard lock(lab.mutex);
            for (const auto& v : state["vehicles"]) {
                const int id = v["id"];
                if (!lab.states[id].count(v["state_stamp_ns"].get<uint64_t>())) return false;
                if (v["pose_from"] == "vehicleObservation" && !lab.seen[id].count(v["pose_stamp_ns"].get<uint64_t>())) return false;
            }
            return true;
        };
        (void)wait_until(
            [&] {
                state = api_state(port);
                return wait_until(test_has_its_samples, 1s, 50ms);
            },
            10s, 0ms);
        std::lock_guard lock(lab.mutex);
        for (const auto& v : state["vehicles"]) {
            const int id = v["id"];
            auto s = lab.states[id].find(v["state_stamp_ns"].get<uint64_t>());
            ASSERT_NE(s, lab.states[id].end()) << "car " << id << ": the test saw the VehicleState the monitor shows";
            EXPECT_DOUBLE_EQ(v["speed"], s->second.speed());
            EXPECT_DOUBLE_EQ(v["battery_voltage"], s->second.battery_voltage());
            ASSERT_EQ(v["pose_from"], "vehicleObservation");
            auto o = lab.seen[id].find(v["pose_stamp_ns"].get<uint64_t>());
            ASSERT_NE(o, lab.seen[id].end()) << "car " << id;
            EXPECT_DOUBLE_EQ(v["x"], o->second.pose().x());
            EXPECT_DOUBLE_EQ(v["y"], o->second.pose().y());
            EXPECT_FALSE(v["fsm_state"].is_null()) << "car " << id << "'s state machine";
        }
    }

    cpm_test::Browser browser;
    browser.open("http://127.0.0.1:" + std::to_string(port) + "/");
    ASSERT_TRUE(browser.wait_for("window.cpmMonitor.updates > 5 && document.querySelectorAll('#cars .car').length === 4", 30s))
        << browser.eval("JSON.stringify(window.cpmMonitor)").dump();

    // Stop one car that is driving, with its own button.
    int target = 0;
    ASSERT_TRUE(wait_until(
        [&] {
            const auto state = api_state(port);
            for (const auto& v : state["vehicles"]) {
                if (v["speed"].is_number() && v["speed"].get<double>() > 0.2 && v["fsm_state"] != "Stop") target = v["id"];
            }
            return target != 0;
        },
        20s, 100ms))
        << "a car is driving";
    browser.eval("document.querySelector('.panel[data-id=\"" + std::to_string(target) + "\"] button.stop').click()");
    EXPECT_TRUE(wait_until([&] { return std::abs(lab.speed(target)) < 0.02; }, 5s, 20ms)) << "car " << target << " stopped";
    EXPECT_TRUE(cpm_test::holds_for([&] { return std::abs(lab.speed(target)) < 0.05; }, 1s, 20ms)) << "and stays stopped";
    EXPECT_TRUE(browser.wait_for("document.getElementById('stop-result').textContent.includes('car " + std::to_string(target) + "')", 5s));
    EXPECT_TRUE(wait_until(
        [&] {
            const auto state = api_state(port);
            for (const auto& v : state["vehicles"]) {
                if (v["id"] == target) return v["fsm_state"] == "StoppedByRequest";
            }
            return false;
        },
        kStateWait, 100ms))
        << "its state machine says why";

    EXPECT_EQ(browser.eval("document.getElementById('source').textContent"), "live");
    const int before = browser.eval("window.cpmMonitor.received");
    std::this_thread::sleep_for(2s);
    const int after = browser.eval("window.cpmMonitor.received");
    EXPECT_GE(after - before, 40) << "at least 20 updates a second";
    EXPECT_EQ(browser.eval("document.querySelectorAll('#walls line').length"), 8) << "the loop's eight walls";
    EXPECT_EQ(browser.eval("document.querySelectorAll('.panel').length"), 4) << "a panel per car";

    // Stop every car, then compare where the page draws them with where they are. The click
    // comes while another car drives (a stop that came too late to matter would prove nothing):
    // on a loaded machine the cars may be braking for a stale state at any one look.
    std::vector<int> driving;
    nlohmann::json at_click;
    const bool someone_drives = wait_until(
        [&] {
            at_click = api_state(port);
            driving.clear();
            for (const auto& v : at_click["vehicles"]) {
                if (v["id"] != target && v["speed"].is_number() && std::abs(v["speed"].get<double>()) > 0.1 && v["fsm_state"] != "Stop") {
                    driving.push_back(v["id"].get<int>());
                }
            }
            return !driving.empty();
        },
        10s, 50ms);
    ASSERT_TRUE(someone_drives) << "no other car drove within 10 s, to be stopped by 'stop all': " << at_click.dump();
    browser.eval("document.getElementById('stop-all').click()");
    EXPECT_TRUE(wait_until(
        [&] {
            const auto state = api_state(port);
            for (int id : driving) {
                for (const auto& v : state["vehicles"]) {
                    if (v["id"] == id && v["fsm_state"] != "StoppedByRequest") return false;
                }
            }
            return true;
        },
        kStateWait, 100ms))
        << "every car that drove was stopped by the request: " << api_state(port).dump();
    EXPECT_TRUE(wait_until(
        [&] {
            for (int id = 1; id <= 4; ++id) {
                if (std::abs(lab.speed(id)) > 0.01) return false;
            }
            return true;
        },
        8s, 50ms))
        << "every car stopped";
    std::this_thread::sleep_for(500ms);
    const auto drawn = browser.eval(kDrawnCars);
    ASSERT_EQ(drawn.size(), 4u) << drawn.dump();
    for (const auto& car : drawn) {
        const int id = car["id"];
        std::lock_guard lock(lab.mutex);
        ASSERT_FALSE(lab.seen[id].empty());
        const auto& pose = lab.seen[id].rbegin()->second.pose();
        EXPECT_NEAR(car["x"].get<double>(), pose.x(), 0.05) << "car " << id << " drawn at " << car.dump();
        EXPECT_NEAR(car["y"].get<double>(), pose.y(), 0.05) << "car " << id << " drawn at " << car.dump();
        EXPECT_EQ(car["visible"], true) << "car " << id << " is inside the map";
    }
    const std::string shot = (fs::current_path() / "monitor_e2e.png").string();  // kept beside the test, to look at
    browser.screenshot(shot);
    EXPECT_GT(fs::file_size(shot), 20000u);

    run.kill(SIGINT);
    EXPECT_EQ(run.wait(60s), 1) << "stopped by Ctrl-C: not a full run\n" << run.errors();
    ASSERT_TRUE(fs::exists(out + "/recording.db"));

    // The same recording played back to a monitor without --allow-stop: a replay, and no stops.
    Process watch({built_program("cpm"), "monitor", "--port", "0", "--world", cpm_test::source_dir() + "/scenarios/maps/loop.json"});
    std::smatch m;
    std::string said;  // m points into it: it must outlive the wait (TSan saw a use after free)
    ASSERT_TRUE(wait_until(
        [&] {
            said = watch.output();
            return std::regex_search(said, m, std::regex("at (http://127\\.0\\.0\\.1:([0-9]+)/)"));
        },
        20s, 50ms))
        << watch.output() << watch.errors();
    const std::string url = m[1];
    const int watch_port = std::stoi(m[2]);
    Process play({built_program("cpm"), "play", out + "/recording.db"});
    browser.open(url);
    EXPECT_TRUE(browser.wait_for("document.getElementById('source').textContent === 'replay (cpm play)'", 20s))
        << browser.eval("document.getElementById('source').textContent").dump();
    EXPECT_TRUE(browser.wait_for("document.querySelectorAll('#cars .car').length === 4", 20s));
    EXPECT_EQ(browser.eval("document.getElementById('stop-all').disabled"), true);
    EXPECT_EQ(browser.eval("[...document.querySelectorAll('.panel button.stop')].every(b => b.disabled)"), true);
    EXPECT_EQ(browser.eval("fetch('/api/stop', {method: 'POST', body: '{\"vehicle_id\": 1}'}).then(r => r.status)"), 403);
    EXPECT_EQ(api_state(watch_port)["source"], "replay");
    // The replay carries the state machines and the log as the live run did (cpm play offers
    // them as the lab's writers do, so the monitor's transient-local readers match).
    EXPECT_TRUE(wait_until(
        [&] {
            const auto state = api_state(watch_port);
            if (!state.contains("log") || state["log"].empty() || state["vehicles"].size() != 4) return false;
            for (const auto& v : state["vehicles"]) {
                if (v["fsm_state"].is_null()) return false;
            }
            return true;
        },
        20s, 100ms))
        << api_state(watch_port).dump();
    EXPECT_TRUE(browser.wait_for("document.querySelectorAll('#log tbody tr').length > 0 && "
                                 "[...document.querySelectorAll('.panel [data-field=\"state\"]')].every(d => d.textContent !== '–')",
                                 10s))
        << browser.eval("document.body.innerText").dump();
    play.kill(SIGINT);
    play.wait(20s);
    watch.kill(SIGINT);
    EXPECT_EQ(watch.wait(20s), 0) << watch.errors();
}
