// The `cpm` command as a user meets it: --help and --version, every command-line error with exit
// code 2 and one prefix, and output that cannot be written is an error.
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/init.hpp>
#include <cpm/stamp_message.hpp>
#include <cpm_test/Isolation.hpp>
#include <cpm_test/Process.hpp>
#include <cpm_test/SourceDir.hpp>
#include <cpm_test/TempDir.hpp>

#include <VehicleState.h>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <map>
#include <nlohmann/json.hpp>

#include <atomic>
#include <cstdio>
#include <fstream>
#include <unistd.h>
#include <sstream>
#include <thread>

using namespace std::chrono_literals;
using ::testing::HasSubstr;
using ::testing::Not;
using cpm_test::Process;

namespace {

Process run_cpm(std::vector<std::string> args)
{
    args.insert(args.begin(), cpm_test::built_program("cpm"));
    return Process(args);
}

TEST(CpmCommand, AnswersVersionAndHelpForEveryGroup)
{
    cpm_test::test_domain_id();
    auto version = run_cpm({"--version"});
    EXPECT_EQ(version.wait(10s), 0);
    EXPECT_THAT(version.output(), HasSubstr("cpm 0."));
    EXPECT_THAT(version.output(), HasSubstr("Fast DDS 2."));
    for (const char* group : {"lab", "topic", "param", "fsm", "vehicle"}) {
        auto help = run_cpm({group, "--help"});
        EXPECT_EQ(help.wait(10s), 0) << group << help.errors();
        EXPECT_THAT(help.output(), HasSubstr(std::string("cpm ") + group + " VERB")) << group;
    }
    auto top = run_cpm({"--help"});
    EXPECT_EQ(top.wait(10s), 0);
    EXPECT_THAT(top.output(), HasSubstr("fsm render"));
    auto history = run_cpm({"history", "at", "--help"});
    EXPECT_EQ(history.wait(10s), 0);
    EXPECT_THAT(history.output(), HasSubstr("usage: cpm history"));
}

TEST(CpmCommand, CommandLineErrorsExitWithTwoAndNameWhatIsWrongOnce)
{
    cpm_test::test_domain_id();
    auto domain = run_cpm({"dump", "--dds_domain", "abc"});
    EXPECT_EQ(domain.wait(10s), 2);
    EXPECT_THAT(domain.errors(), HasSubstr("cpm: --dds_domain: 'abc' is not a whole number"));
    auto domain_first = run_cpm({"--dds_domain", "abc", "dump"});
    EXPECT_EQ(domain_first.wait(10s), 2);
    EXPECT_THAT(domain_first.errors(), HasSubstr("--dds_domain: 'abc'"));
    auto interface = run_cpm({"dump", "--dds_interface", "10.0.0.1"});
    EXPECT_EQ(interface.wait(10s), 2);
    EXPECT_THAT(interface.errors(), HasSubstr("'10.0.0.1' is neither an interface nor an IPv4 address of this host"));
    auto missing = run_cpm({"history", "at", "--topic", "--key", "1"});
    EXPECT_EQ(missing.wait(10s), 2);
    EXPECT_EQ(missing.errors(), "cpm history at: --topic needs a value\n");  // one prefix, not "cpm: cpm history at:"
    auto unknown = run_cpm({"history", "nope"});
    EXPECT_EQ(unknown.wait(10s), 2);
    EXPECT_THAT(unknown.errors(), HasSubstr("cpm: unknown command 'cpm history nope'"));
    auto group_only = run_cpm({"fsm"});
    EXPECT_EQ(group_only.wait(10s), 2);
    EXPECT_THAT(group_only.errors(), HasSubstr("fsm check"));
}

TEST(CpmCommand, EveryHistoryVerbNamesWhatIsMissingOrWrongBeforeAskingTheService)
{
    cpm_test::test_domain_id();
    struct Case
    {
        std::vector<std::string> args;
        std::string message;  // the whole first line of stderr
    };
    const std::vector<Case> cases{
        {{"history", "list", "extra"}, "cpm history list: unexpected argument 'extra'"},
        {{"history", "search", "--alive-at", "2026-02-30T00:00:00Z"}, "cpm history search: --alive-at: '2026-02-30T00:00:00Z' is not a date and time that exists"},
        {{"history", "search", "--parent", "7.x"}, "cpm history search: --parent: '7.x' is not an oid (as cpm dump prints it: 7, or 7.2 for slot 7's second object)"},
        {{"history", "latest"}, "cpm history latest: --topic NAME (and --key K) is required"},
        {{"history", "latest", "--topic", "vehicleState", "--by", "arrival"}, "cpm history latest: --by 'arrival': expected commit or data"},
        {{"history", "at", "--topic", "vehicleState"}, "cpm history at: --time T is required (ns, ISO-8601 or relative such as -2s)"},
        {{"history", "older", "--topic", "vehicleState", "--time", "-2 s"}, "cpm history older: --time: '-2 s' is not a relative time (a sign and a duration with its unit: -2s, +500ms)"},
        {{"history", "younger", "--topic", "vehicleState", "--time", "2026-11-23T14:05:00+25:00"}, "cpm history younger: --time: '2026-11-23T14:05:00+25:00' has a zone offset beyond 23:59"},
        {{"history", "range", "--topic", "vehicleState", "--from", "-1s"}, "cpm history range: --from T and --to T are required"},
        {{"history", "range", "--topic", "vehicleState", "--from", "now", "--to", "-5s"}, "cpm history range: --to is before --from"},
        {{"history", "range", "--topic", "vehicleState", "--from", "-5s", "--to", "now", "--limit", "0"}, "cpm history range: --limit: '0' is not a whole number in 1..100000"},
        {{"history", "successor", "--topic", "vehicleState", "--timeout", "1parsec"}, "cpm history successor: --timeout: '1parsec' is not a duration"},
        {{"history", "snapshot", "--time", "now"}, "cpm history snapshot: --objects TOPIC[/KEY],... is required"},
        {{"history", "snapshot", "--time", "now", "--objects", "a,,b"}, "cpm history snapshot: --objects: empty item in 'a,,b'"},
        {{"history", "changes"}, "cpm history changes: --since T is required"},
        {{"history", "at", "--topic", "vehicleState", "--time", "20s"}, "cpm history at: --time: '20s' is a time into a run, which only a recording has (--file)"},
        {{"history", "teleport"}, "cpm: unknown command 'cpm history teleport' (see cpm history --help)"},
        {{"dump", "--alive", "now"}, "cpm dump: unexpected argument 'now'"},
    };
    for (const auto& c : cases) {
        auto p = run_cpm(c.args);
        EXPECT_EQ(p.wait(10s), 2) << c.message << "\n" << p.errors();
        const std::string first_line = p.errors().substr(0, p.errors().find('\n'));
        EXPECT_THAT(first_line, HasSubstr(c.message));
        EXPECT_EQ(p.output(), "") << c.message;
    }
    for (const char* verb : {"list", "latest", "snapshot", "changes"}) {
        auto help = run_cpm({"history", verb, "--help"});
        EXPECT_EQ(help.wait(10s), 0) << verb;
        EXPECT_THAT(help.output(), HasSubstr("usage: cpm history")) << verb;
    }
    auto dump_help = run_cpm({"dump", "--help"});
    EXPECT_EQ(dump_help.wait(10s), 0);
    EXPECT_THAT(dump_help.output(), HasSubstr("usage: cpm dump"));
}

TEST(CpmCommand, WithNoHistoryServiceOnTheDomainTheCommandSaysSoAndExitsOne)
{
    cpm_test::test_domain_id();  // this test's own domain: nothing answers there
    for (std::vector<std::string> args : {std::vector<std::string>{"dump", "--alive"},
                                          {"history", "at", "--topic", "vehicleState", "--key", "3", "--time", "2026-11-23T14:05:00.25Z"},
                                          {"history", "snapshot", "--objects", "vehicleState/3", "--time", "-2s"}}) {
        auto p = run_cpm(args);
        EXPECT_EQ(p.wait(30s), 1) << args[1];
        EXPECT_THAT(p.errors(), HasSubstr("no history service answers on this domain (is cpm_history running?)")) << args[1];
    }
}

TEST(CpmCommand, HostPortsNamesEachPortThatCannotBeTakenAndExitsOne)
{
    const cpm_test::HeldTcpPort taken;
    const std::string busy = "tcp:" + std::to_string(taken.port()), free = "tcp:" + std::to_string(cpm_test::free_tcp_port());
    cpm_test::Process both({cpm_test::built_program("cpm"), "host", "ports", free, busy});
    EXPECT_EQ(both.wait(10s), 1);
    EXPECT_EQ(both.output(), busy + " Address already in use\n");
    cpm_test::Process none({cpm_test::built_program("cpm"), "host", "ports", free});
    EXPECT_EQ(none.wait(10s), 0);
    EXPECT_EQ(none.output(), "");
    cpm_test::Process wrong({cpm_test::built_program("cpm"), "host", "ports", "sctp:80"});
    EXPECT_EQ(wrong.wait(10s), 2);
    EXPECT_THAT(wrong.errors(), HasSubstr("'sctp:80' is not PROTOCOL:PORT with tcp or udp"));
}

TEST(CpmCommand, OutputThatCannotBeWrittenIsAnError)
{
    cpm_test::test_domain_id();
    Process full({"/bin/sh", "-c", cpm_test::built_program("cpm") + " fsm check " + cpm_test::source_dir() + "/scenarios/fsm/corridor.json > /dev/full"});
    EXPECT_EQ(full.wait(10s), 1);
    EXPECT_THAT(full.errors(), HasSubstr("cpm: cannot write the output: No space left on device"));
    auto fine = run_cpm({"fsm", "check", cpm_test::source_dir() + "/scenarios/fsm/corridor.json"});
    EXPECT_EQ(fine.wait(10s), 0);
    EXPECT_THAT(fine.errors(), Not(HasSubstr("cannot write")));
}

}  // namespace

namespace {

/// Writes vehicle 3's state on `topic` at about 50 Hz from a thread until destroyed.
class StateWriter
{
public:
    explicit StateWriter(const std::string& topic, std::vector<uint8_t> ids = {3}) : ids_(std::move(ids)), writer_(topic), thread_([this] { run(); }) {}
    ~StateWriter()
    {
        stop_ = true;
        thread_.join();
    }

private:
    void run()
    {
        VehicleState s;
        for (int i = 0; !stop_; ++i) {
            for (uint8_t id : ids_) {
                s.vehicle_id(id);
                s.pose().x(0.25);
                s.speed(1.5);
                cpm::stamp_message(s, cpm::get_time_ns(), 0);
                (void)writer_.write(s);
            }
            std::this_thread::sleep_for(20ms);
        }
    }
    std::vector<uint8_t> ids_;
    cpm::Writer<VehicleState> writer_;
    std::atomic<bool> stop_{false};
    std::thread thread_;
};

}  // namespace

TEST(CpmTopic, ListInfoEchoAndHzSeeATopicFromDiscoveryAlone)
{
    cpm_test::test_domain_id();
    const std::string topic = cpm_test::unique_topic("probeState");
    StateWriter writer(topic);

    auto list = run_cpm({"topic", "list", "--json"});
    ASSERT_EQ(list.wait(20s), 0) << list.errors();
    bool listed = false;
    std::istringstream lines(list.output());
    for (std::string l; std::getline(lines, l);) {
        auto j = nlohmann::json::parse(l);
        if (j["topic"] == topic) {
            listed = true;
            EXPECT_EQ(j["type"], "VehicleState");
            EXPECT_EQ(j["writers"], 1);
            EXPECT_EQ(j["keyed"], true);
        }
    }
    EXPECT_TRUE(listed) << list.output();

    auto info = run_cpm({"topic", "info", topic, "--json"});
    ASSERT_EQ(info.wait(20s), 0) << info.errors();
    auto i = nlohmann::json::parse(info.output());
    EXPECT_EQ(i["key"], nlohmann::json::array({"vehicle_id"}));
    ASSERT_EQ(i["writers"].size(), 1u);
    EXPECT_EQ(i["writers"][0]["reliability"], "best_effort");

    auto echo = run_cpm({"topic", "echo", topic, "--json", "--count", "3"});
    ASSERT_EQ(echo.wait(20s), 0) << echo.errors();
    std::istringstream samples(echo.output());
    int n = 0;
    for (std::string l; std::getline(samples, l); ++n) {
        auto j = nlohmann::json::parse(l);
        EXPECT_EQ(j["data"]["vehicle_id"], 3);
        EXPECT_DOUBLE_EQ(j["data"]["pose"]["x"].get<double>(), 0.25);
        EXPECT_DOUBLE_EQ(j["data"]["speed"].get<double>(), 1.5);
    }
    EXPECT_EQ(n, 3);

    auto hz = run_cpm({"topic", "hz", topic, "--json", "--duration", "2500ms"});
    ASSERT_EQ(hz.wait(20s), 0) << hz.errors();
    std::istringstream reports(hz.output());
    std::string last;
    for (std::string l; std::getline(reports, l);) last = l;
    ASSERT_FALSE(last.empty()) << hz.output();
    auto r = nlohmann::json::parse(last);
    // A 20 ms sleep loop on a shared 2-core machine: loose bounds; what matters is that it is measured.
    EXPECT_GT(r["rate_hz"].get<double>(), 10.0);
    EXPECT_LT(r["rate_hz"].get<double>(), 60.0);
    EXPECT_LE(r["min_s"].get<double>(), r["mean_s"].get<double>());
    EXPECT_GE(r["max_s"].get<double>(), r["mean_s"].get<double>());
    EXPECT_GT(r["samples"].get<int>(), 20);

    auto nobody = run_cpm({"topic", "echo", cpm_test::unique_topic("nobody"), "--wait", "300ms"});
    EXPECT_EQ(nobody.wait(20s), 1);
    EXPECT_THAT(nobody.errors(), HasSubstr("no writer of topic"));
}

TEST(CpmTopic, HzOfAKeyedTopicIsPerKeyThenEveryKeyTogether)
{
    cpm_test::test_domain_id();
    const std::string topic = cpm_test::unique_topic("twoCars");
    StateWriter writer(topic, {3, 4});  // both cars in the same loop: every period two samples at once

    auto hz = run_cpm({"topic", "hz", topic, "--json", "--duration", "2500ms"});
    ASSERT_EQ(hz.wait(20s), 0) << hz.errors();
    std::map<std::string, nlohmann::json> last;  // the last report of each key, and of all ("instances")
    std::istringstream reports(hz.output());
    for (std::string l; std::getline(reports, l);) {
        auto j = nlohmann::json::parse(l);
        last[j.contains("key") ? j["key"].get<std::string>() : "all " + std::to_string(j["instances"].get<int>())] = j;
    }
    ASSERT_EQ(last.size(), 3u) << hz.output();
    ASSERT_TRUE(last.count("3") && last.count("4") && last.count("all 2")) << hz.output();
    for (const char* key : {"3", "4"}) {
        const auto& r = last[key];
        EXPECT_EQ(r["topic"], topic);
        EXPECT_GT(r["rate_hz"].get<double>(), 10.0) << r.dump();
        EXPECT_LT(r["rate_hz"].get<double>(), 60.0) << r.dump();
        // The mean gap, not the least: gaps are measured on arrival, and a busy machine hands a
        // reader two of one car's samples at once now and then (10 us apart, after a 90 ms gap).
        EXPECT_GT(r["mean_s"].get<double>(), 0.015) << "one car's samples are a period (20 ms) apart, not the two cars' 10 ms: " << r.dump();
    }
    EXPECT_NEAR(last["all 2"]["rate_hz"].get<double>(), last["3"]["rate_hz"].get<double>() + last["4"]["rate_hz"].get<double>(),
                0.2 * last["all 2"]["rate_hz"].get<double>())
        << "together they are the sum";

    auto one = run_cpm({"topic", "hz", topic, "--key", "4", "--duration", "1500ms"});
    ASSERT_EQ(one.wait(20s), 0) << one.errors();
    EXPECT_THAT(one.output(), HasSubstr(topic + "/4"));
    EXPECT_THAT(one.output(), Not(HasSubstr(topic + "/3")));
    EXPECT_THAT(one.output(), Not(HasSubstr("all ")));
}

TEST(CpmPrograms, BadFlagsAndFilesOfEveryProgramAreNamedWithTheRightExitCode)
{
    cpm_test::test_domain_id();
    struct Case
    {
        std::vector<std::string> argv;
        std::string file_text;  // written to the file the arguments name as FILE, if any
        int code;
        std::string message;
    };
    const std::string file = "/tmp/cpm_program_errors_" + std::to_string(::getpid()) + ".json";
    const std::vector<Case> cases{
        {{"cpm_history", "--include", "("}, "", 2, "--include '(' is not a regular expression"},
        {{"cpm_history", "--exclude", "a[", "--window", "1s"}, "", 2, "--exclude 'a[' is not a regular expression"},
        {{"cpm_history", "--max-bytes", "abc"}, "", 2, "--max-bytes: 'abc' is not a whole number"},
        {{"cpm_history", "--max-bytes-total", "12"}, "", 2, "--max-bytes-total: '12' is not a whole number in 1024..1099511627776"},
        {{"cpm_history", "--max-bytes", "2048", "--max-bytes-total", "4096"}, "", 2, "--max-bytes is the older name of --max-bytes-total"},
        {{"fsm_node", "--vehicle_id", "1", "--fsm", cpm_test::source_dir() + "/scenarios/fsm/corridor.json", "--max-age", "abc"},
         "", 2, "--max-age: 'abc' is not a duration"},
        {{"vehicle_bridge", "--vehicle_id", "1", "--device", "/dev/null", "--calibration", "FILE"}, R"({"servo_range_us": 0})",
         1, "servo_range_us must not be 0"},
        {{"vehicle_bridge", "--vehicle_id", "1", "--device", "/dev/null", "--calibration", "FILE"}, R"({"max_speed": 500})",
         1, "$.max_speed: 500 is out of range [0.01, 100]"},
        {{"vehicle_bridge", "--vehicle_id", "1", "--device", "/dev/null", "--calibration", "FILE"},
         R"({"battery_min_voltage": 9, "battery_max_voltage": 8})", 1, "battery_min_voltage must be below battery_max_voltage"},
        {{"firmware_sim", "--vehicle_id", "1", "--params", "FILE"}, R"({"wheelbase": -1})", 1, "$.wheelbase: -1 is out of range [0.01, inf]"},
    };
    for (const auto& c : cases) {
        std::vector<std::string> argv{cpm_test::built_program(c.argv[0])};
        for (size_t i = 1; i < c.argv.size(); ++i) argv.push_back(c.argv[i] == "FILE" ? file : c.argv[i]);
        if (!c.file_text.empty()) std::ofstream(file) << c.file_text;
        Process p(argv);
        EXPECT_EQ(p.wait(10s), c.code) << c.argv[0] << " " << c.message << "\n" << p.errors();
        EXPECT_THAT(p.errors(), HasSubstr(c.message)) << c.argv[0];
        if (!c.file_text.empty()) {
            EXPECT_THAT(p.errors(), HasSubstr(file)) << "the file is not named";
        }
    }
    std::remove(file.c_str());
}

TEST(CpmPrograms, AFolderGivenForAFileIsNamedAsAFolder)
{
    cpm_test::test_domain_id();
    const std::string dir = cpm_test::source_dir() + "/scenarios/labs";
    const std::vector<std::pair<std::vector<std::string>, std::string>> cases{
        {{"lab", "check", dir}, dir + ": cannot read it as the scenario file: it is a directory"},
        {{"aruco", "detect", "x.png", "--camera", dir}, dir + ": cannot read it as the camera file: it is a directory"},
        {{"history", "--file", dir, "latest", "--topic", "vehicleState"}, "recording " + dir + ": it is a directory"},
        {{"dump", "--file", dir}, "recording " + dir + ": it is a directory"},
        {{"play", dir}, "recording " + dir + ": it is a directory"},
        {{"record", "import", dir, "--topic", "t", "--type", "VehicleState", "--out", "/tmp/never.db"},
         dir + ": cannot read it as the CSV file: it is a directory"},
    };
    for (const auto& [args, message] : cases) {
        auto p = run_cpm(args);
        EXPECT_EQ(p.wait(20s), 1) << args[0] << " " << args[1] << "\n" << p.errors();
        EXPECT_THAT(p.errors(), HasSubstr(message)) << args[0] << " " << args[1];
        EXPECT_THAT(p.errors(), Not(HasSubstr("underflow"))) << args[0] << " " << args[1];
        EXPECT_THAT(p.errors(), Not(HasSubstr("disk I/O"))) << args[0] << " " << args[1];
    }
}

// `cpm lab check` of a good file: what a run would start, and how long it would wait before it
// ends naming what it waited for (the scenario's timeouts, or the defaults), nothing started.
TEST(CpmLab, CheckSaysWhatARunStartsAndHowLongItWaits)
{
    cpm_test::test_domain_id();
    auto shipped = run_cpm({"lab", "check", cpm_test::source_dir() + "/scenarios/labs/gates.yaml"});
    ASSERT_EQ(shipped.wait(20s), 0) << shipped.errors();
    EXPECT_THAT(shipped.output(), HasSubstr("gates, 1 car(s), real time, 90.0 s"));
    EXPECT_THAT(shipped.output(), HasSubstr("a run starts 7 processes"));
    EXPECT_THAT(shipped.output(), HasSubstr("  fsm_6 "));
    EXPECT_THAT(shipped.output(), HasSubstr("waits 30 s for its processes to start, 10 s for each step of simulated time"));

    // The shipped corridor with timeouts of its own, its files named from the shipped folder.
    cpm_test::TempDir dir;
    std::string text = cpm_test::file_text(cpm_test::source_dir() + "/scenarios/labs/corridor.yaml");
    for (size_t at; (at = text.find(" ../")) != std::string::npos;) text.replace(at, 4, " " + cpm_test::source_dir() + "/scenarios/");
    auto own = run_cpm({"lab", "check", dir.write("corridor.yaml", text + "timeouts: {start: 2m, step: 1.5s}\n")});
    EXPECT_EQ(own.wait(20s), 0) << own.errors();
    EXPECT_THAT(own.output(), HasSubstr("waits 120 s for its processes to start, 1.5 s for each step of simulated time"));
}
