// Each of cpm's programs, started for real on this test's domain, writes and reads exactly what
// its row of cpm/nodes.hpp says (beyond what every program has): the table that a run's plan and
// its security grants come from is checked against what the programs do, by DDS discovery.
#include <cpm/Participant.hpp>
#include <cpm/nodes.hpp>
#include <cpm_test/Dds.hpp>
#include <cpm_test/Isolation.hpp>
#include <cpm_test/Process.hpp>
#include <cpm_test/TempDir.hpp>
#include <cpm_test/SourceDir.hpp>

#include <gtest/gtest.h>

#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <set>

using namespace std::chrono_literals;
using cpm_test::built_program;

namespace {

const std::string kRoot = cpm_test::source_dir();

struct Endpoints
{
    std::set<std::string> writers, readers;
};

/// A participant that hears of every writer and reader on the domain, by participant name.
class Probe
{
public:
    Probe()
    {
        auto options = cpm_test::isolated_options();
        options.name = "nodes_table_probe";
        options.on_discovery = [this](const cpm::DiscoveryEvent& e) {
            std::lock_guard<std::mutex> lock(mutex_);
            if (e.kind == cpm::DiscoveryEvent::Kind::participant_found) names_[e.prefix()] = e.participant_name;
            if (e.kind == cpm::DiscoveryEvent::Kind::writer_found) seen_[e.prefix()].writers.insert(e.topic);
            if (e.kind == cpm::DiscoveryEvent::Kind::reader_found) seen_[e.prefix()].readers.insert(e.topic);
        };
        participant_ = std::make_unique<cpm::Participant>(options);
    }
    /// The endpoints of the participant named `name` (several with one name: merged).
    Endpoints of(const std::string& name)
    {
        std::lock_guard<std::mutex> lock(mutex_);
        Endpoints out;
        for (const auto& [prefix, n] : names_) {
            if (n != name) continue;
            out.writers.insert(seen_[prefix].writers.begin(), seen_[prefix].writers.end());
            out.readers.insert(seen_[prefix].readers.begin(), seen_[prefix].readers.end());
        }
        return out;
    }

private:
    std::mutex mutex_;
    std::map<std::array<uint8_t, 12>, std::string> names_;
    std::map<std::array<uint8_t, 12>, Endpoints> seen_;
    std::unique_ptr<cpm::Participant> participant_;
};

bool is_pattern(const std::string& t) { return t.find_first_of("*?") != std::string::npos; }

std::string listed(const std::set<std::string>& s)
{
    std::string out;
    for (const auto& t : s) out += (out.empty() ? "" : ", ") + t;
    return out;
}

/// The row's exact topics it has not (yet) been seen writing or reading.
std::vector<std::string> missing(const cpm::nodes::NodeSpec& row, const Endpoints& seen)
{
    std::vector<std::string> out;
    for (const auto& t : row.publish) {
        if (!is_pattern(t) && !seen.writers.count(t)) out.push_back("writes " + t);
    }
    for (const auto& t : row.subscribe) {
        if (!is_pattern(t) && !seen.readers.count(t)) out.push_back("reads " + t);
    }
    return out;
}

}  // namespace

TEST(NodesTable, EachProgramWritesAndReadsWhatItsRowSays)
{
    cpm_test::test_domain_id();
    cpm_test::TempDir dir;
    Probe probe;
    const std::string map = kRoot + "/scenarios/maps/gates.json", camera = kRoot + "/scenarios/cameras/sim_640x480.yaml";
    const std::string link = (dir.path / "car_6.tty").string();
    // The program each row is, as a run starts it (the participant is named by --node_id or the program).
    std::vector<std::unique_ptr<cpm_test::Process>> running;
    auto start = [&](std::vector<std::string> argv) { running.push_back(std::make_unique<cpm_test::Process>(std::move(argv))); };
    start({built_program("firmware_sim"), "--vehicle_id", "6", "--map", map, "--start", "0,0,0.3", "--link", link});
    ASSERT_TRUE(cpm_test::wait_until([&] { return std::filesystem::exists(link); }, 20s)) << running.back()->errors();
    start({built_program("vehicle_bridge"), "--vehicle_id", "6", "--device", link, "--start", "0,0,0.3"});
    start({built_program("camera_sim"), "--vehicle_id", "6", "--camera", camera, "--map", map, "--rate", "5"});
    start({built_program("aruco_node"), "--vehicle_id", "6", "--camera", camera, "--world", map});
    // Beside a positioning system: a simulator writing its truth to a topic of its own, the
    // overhead camera drawing from it, and ips_node (a row is what a program may use in any mode).
    const std::string ceiling = kRoot + "/scenarios/cameras/ceiling_1280x1024.yaml", floor = kRoot + "/scenarios/maps/lab_floor.json";
    start({built_program("firmware_sim"), "--vehicle_id", "7", "--start", "2,2,0", "--truth_topic", "vehicleObservationTruth"});
    start({built_program("camera_sim"), "--overhead", "--camera", ceiling, "--map", floor, "--rate", "5"});
    start({built_program("ips_node"), "--camera", ceiling, "--world", floor});
    start({built_program("fsm_node"), "--vehicle_id", "6", "--fsm", kRoot + "/scenarios/fsm/gates.json"});
    start({built_program("central_routing"), "--vehicle_ids", "6", "--lanes", kRoot + "/scenarios/lanes/ring.json", "--period", "100ms"});
    start({built_program("cpm_history"), "--window", "10s"});
    start({built_program("cpm"), "param", "serve", dir.write("p.json", R"({"speed": 1})"), "--node_id", "parameter_server"});
    start({built_program("cpm"), "monitor", "--port", std::to_string(cpm_test::free_tcp_port()), "--allow-stop", "--node_id", "monitor"});

    const std::vector<std::string> programs{"firmware_sim", "vehicle_bridge", "camera_sim", "aruco_node", "ips_node", "fsm_node",
                                            "central_routing", "cpm_history", "parameter_server", "monitor"};
    const bool all_seen = cpm_test::wait_until([&] {
        for (const auto& p : programs) {
            if (!missing(cpm::nodes::find(p), probe.of(p)).empty()) return false;
        }
        return true;
    }, 40s, 50ms);
    std::this_thread::sleep_for(1s);  // an endpoint the row does not name would come with the others

    // Beyond its row, a program may use what every program has (log, timer, parameters, history).
    std::vector<std::string> may_write = cpm::nodes::builtin_publish(), may_read = cpm::nodes::builtin_subscribe();
    const auto& history = cpm::nodes::find("history_client");
    may_write.insert(may_write.end(), history.publish.begin(), history.publish.end());
    may_read.insert(may_read.end(), history.subscribe.begin(), history.subscribe.end());
    for (const auto& p : programs) {
        const auto& row = cpm::nodes::find(p);
        const Endpoints seen = probe.of(p);
        SCOPED_TRACE(p + " writes {" + listed(seen.writers) + "}, reads {" + listed(seen.readers) + "}");
        for (const auto& m : missing(row, seen)) ADD_FAILURE() << p << " never " << m << " though its row says so";
        for (const auto& t : seen.writers) {
            EXPECT_TRUE(cpm::nodes::matches(t, row.publish) || cpm::nodes::matches(t, may_write)) << p << " writes " << t << ", not in its row";
        }
        for (const auto& t : seen.readers) {
            EXPECT_TRUE(cpm::nodes::matches(t, row.subscribe) || cpm::nodes::matches(t, may_read)) << p << " reads " << t << ", not in its row";
        }
    }
    EXPECT_TRUE(all_seen);
    for (auto& p : running) EXPECT_EQ(p->errors().find("error"), std::string::npos) << p->errors();
}
