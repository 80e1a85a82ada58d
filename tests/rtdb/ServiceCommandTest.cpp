// cpm_history's flags read into the service's options without a process: defaults, every
// flag, and each wrong one named.
#include <cpm/rtdb/ServiceCommand.hpp>

#include <gtest/gtest.h>

using namespace cpm::rtdb;

namespace {

ServiceCommand read(std::vector<std::string> args)
{
    return read_service_flags(cpm::cli::parse_flags(args, service_flags(), "cpm_history"));
}

std::string error_of(std::vector<std::string> args)
{
    try {
        (void)read(std::move(args));
    } catch (const cpm::cli::UsageError& e) {
        return e.what();
    }
    return "";
}

}  // namespace

TEST(ServiceCommand, DefaultsAndEveryFlagReachTheOptions)
{
    const auto plain = read({});
    EXPECT_EQ(plain.options.window_ns, 10'000'000'000ull);
    EXPECT_EQ(plain.options.max_bytes_total, 512ull << 20);
    EXPECT_EQ(plain.options.max_bytes_per_topic, 128ull << 20);
    EXPECT_TRUE(plain.record_path.empty());

    const auto c = read({"--include", "vehicle.*", "--include", "log", "--exclude", "cameraFrame", "--window", "60s", "--topic-window",
                         "vehicleState=2m", "--max-bytes", "4096", "--max-bytes-per-topic", "2048", "--status-period", "250ms", "--record",
                         "/tmp/r.db", "--record-name", "run", "--record-max-bytes", "65536"});
    EXPECT_EQ(c.options.include, (std::vector<std::string>{"vehicle.*", "log"}));
    EXPECT_EQ(c.options.exclude, (std::vector<std::string>{"cameraFrame"}));
    EXPECT_EQ(c.options.window_ns, 60'000'000'000ull);
    EXPECT_EQ(c.options.topic_windows_ns.at("vehicleState"), 120'000'000'000ull);
    EXPECT_EQ(c.options.max_bytes_total, 4096u);
    EXPECT_EQ(c.options.max_bytes_per_topic, 2048u);
    EXPECT_EQ(c.options.status_period_ns, 250'000'000ull);
    EXPECT_EQ(c.record_path, "/tmp/r.db");
    EXPECT_EQ(c.record.name, "run");
    EXPECT_EQ(c.record.max_bytes, 65536u);
}

TEST(ServiceCommand, AWrongFlagIsNamedWithItsValue)
{
    EXPECT_EQ(error_of({"--include", "("}).rfind("--include '(' is not a regular expression", 0), 0u);
    EXPECT_EQ(error_of({"--window", "0s"}), "--window must be longer than 0");
    EXPECT_EQ(error_of({"--topic-window", "vehicleState"}),
              "cpm_history: --topic-window 'vehicleState': expected TOPIC=DURATION (e.g. vehicleState=60s)");
    EXPECT_EQ(error_of({"--max-bytes", "4096", "--max-bytes-total", "4096"}),
              "cpm_history: --max-bytes is the older name of --max-bytes-total; give one");
    EXPECT_EQ(error_of({"--record-name", "x"}), "cpm_history: --record-max-bytes, --record-name, --record-format, --foxglove-3d, --record-split and --record-max go with --record FILE");
    EXPECT_NE(error_of({"--max-bytes-per-topic", "12"}).find("--max-bytes-per-topic"), std::string::npos);
}

TEST(ServiceCommand, SaveTriggersAreReadAndAWrongOneIsNamed)
{
    const auto c = read({"--save-on", "stopRequest", "--save-on", "fsmStatus=state_type==Emergency", "--save-on", "fsmStatus=state_id!=3",
                         "--save-before", "5s", "--save-after", "2s", "--save-format", "mcap", "--save-dir", "/tmp"});
    ASSERT_EQ(c.options.save_on.size(), 3u);
    EXPECT_EQ(c.options.save_on[0].topic, "stopRequest");
    EXPECT_EQ(c.options.save_on[0].field, "");
    EXPECT_EQ(c.options.save_on[1].field, "state_type");
    EXPECT_EQ(c.options.save_on[1].value, "Emergency");
    EXPECT_TRUE(c.options.save_on[1].equal);
    EXPECT_FALSE(c.options.save_on[2].equal);
    EXPECT_EQ(c.options.save_before_ns, 5'000'000'000ull);
    EXPECT_EQ(c.options.save_after_ns, 2'000'000'000ull);
    EXPECT_EQ(c.options.save_format, "mcap");
    EXPECT_EQ(c.options.save_dir, "/tmp");
    EXPECT_NE(error_of({"--save-on", "fsmStatus=state_type=Emergency"}).find("has no == or !="), std::string::npos);
    EXPECT_NE(error_of({"--save-on", "fsmStatus=state==Emergency"}).find("FsmStatus has no field 'state' (it has"), std::string::npos);
    EXPECT_NE(error_of({"--save-on", "=x==1"}).find("no topic"), std::string::npos);
    EXPECT_NE(error_of({"--save-on", "stopRequest", "--save-format", "csv"}).find("--save-format 'csv'"), std::string::npos);
    EXPECT_EQ(error_of({"--save-after", "1s"}), "cpm_history: --save-after goes with --save-on");
    EXPECT_NE(error_of({"--save-dir", "/no/such/folder"}).find("no such folder"), std::string::npos);
    EXPECT_EQ(error_of({"--record", "/tmp/x.db", "--record-format", "csv"}), "cpm_history: --record-format 'csv': expected sqlite or mcap");
}

TEST(ServiceCommand, ASplitIsBySizeOrByTimeAndItsLimitGoesWithIt)
{
    const auto by_size = read({"--record", "/tmp/r.db", "--record-split", "500MB", "--record-max", "5GiB"});
    EXPECT_EQ(by_size.record.split_bytes, 500'000'000u);
    EXPECT_EQ(by_size.record.split_ns, 0u);
    EXPECT_EQ(by_size.record.max_total_bytes, 5ull << 30);
    const auto by_time = read({"--record", "/tmp/r.mcap", "--record-split", "10min", "--foxglove-3d"});
    EXPECT_EQ(by_time.record.split_ns, 600'000'000'000u);
    EXPECT_EQ(by_time.record.split_bytes, 0u);
    EXPECT_TRUE(by_time.record.foxglove_3d);
    EXPECT_NE(error_of({"--record", "/tmp/r.db", "--record-split", "5 parsecs"}).find("--record-split: '5 parsecs' is not a duration"), std::string::npos);
    EXPECT_NE(error_of({"--record", "/tmp/r.db", "--record-split", "12XB"}).find("--record-split: '12XB' is not a size"), std::string::npos);
    EXPECT_EQ(error_of({"--record", "/tmp/r.db", "--record-split", "0"}), "cpm_history: --record-split must be more than 0");
    EXPECT_EQ(error_of({"--record", "/tmp/r.db", "--record-max", "1GB"}), "cpm_history: --record-max goes with --record-split (it deletes the oldest files)");
}
