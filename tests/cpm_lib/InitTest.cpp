#include <cpm/CommandLine.hpp>
#include <cpm/Error.hpp>
#include <cpm/init.hpp>
#include <cpm/stamp_message.hpp>

#include <VehicleState.h>

#include <gtest/gtest.h>
#include <gmock/gmock.h>

#include <chrono>
#include <cstdlib>

using ::testing::HasSubstr;

namespace {

cpm::InitSettings parse(std::vector<const char*> args, const char* env = nullptr)
{
    args.insert(args.begin(), "/usr/bin/my_node");
    return cpm::parse_init_settings(static_cast<int>(args.size()), args.data(), env);
}

std::string error_of(std::vector<const char*> args, const char* env = nullptr)
{
    try {
        parse(std::move(args), env);
    } catch (const cpm::Error& e) {
        return e.what();
    }
    return "(no error)";
}

}  // namespace

TEST(Init, DefaultsAreDomainZeroNodeIdFromProgramNameAndNoNetwork)
{
    auto sut = parse({});
    EXPECT_EQ(sut.domain_id, 0);
    EXPECT_EQ(sut.node_id, "my_node");
    EXPECT_TRUE(sut.interfaces.empty());
    EXPECT_TRUE(sut.initial_peers.empty());
    EXPECT_TRUE(sut.discovery_server.empty());
    EXPECT_FALSE(sut.simulated_time);
}

TEST(Init, ReadsFlagsInBothSpellingsAndLeavesOthersAlone)
{
    auto sut = parse({"--dds_domain=7", "--node_id", "planner", "--my_flag=3", "--dds_initial_peer=10.0.0.2",
                      "--dds_initial_peer", "10.0.0.3:7412", "--dds_interface=eth1", "--simulated_time",
                      "--security", "lab/nodes/car"});
    EXPECT_EQ(sut.domain_id, 7);
    EXPECT_EQ(sut.node_id, "planner");
    EXPECT_EQ(sut.initial_peers, (std::vector<std::string>{"10.0.0.2", "10.0.0.3:7412"}));
    EXPECT_EQ(sut.interfaces, (std::vector<std::string>{"eth1"}));
    EXPECT_TRUE(sut.simulated_time);
    EXPECT_EQ(sut.security, "lab/nodes/car");
    EXPECT_FALSE(parse({"--dds_shared_memory", "off"}).shared_memory);
    EXPECT_TRUE(parse({"--dds_shared_memory=on"}).shared_memory);
    EXPECT_TRUE(parse({"--dds_shared_memory=on"}).shared_memory_chosen) << "a lab run passes the choice on";
    if (std::getenv("CPM_SHARED_MEMORY") == nullptr) EXPECT_FALSE(parse({}).shared_memory_chosen) << "the default (on) was not chosen";
    bool takes_value = false;
    EXPECT_TRUE(cpm::is_init_flag("--security", takes_value));
    EXPECT_TRUE(takes_value);
}

TEST(Init, EnvironmentGivesDomainAndFlagOverridesIt)
{
    EXPECT_EQ(parse({}, "12").domain_id, 12);
    EXPECT_EQ(parse({"--dds_domain=3"}, "12").domain_id, 3);
}

TEST(Init, DomainAbove232IsAnErrorNamingFlagAndValue)
{
    const std::string message = error_of({"--dds_domain=233"});
    EXPECT_THAT(message, HasSubstr("--dds_domain"));
    EXPECT_THAT(message, HasSubstr("233"));
    EXPECT_THAT(message, HasSubstr("0..232"));
}

TEST(Init, BadValuesAreErrorsNamingTheirSource)
{
    EXPECT_THAT(error_of({"--dds_domain=abc"}), HasSubstr("--dds_domain: 'abc'"));
    EXPECT_THAT(error_of({"--dds_domain=-1"}), HasSubstr("-1"));
    EXPECT_THAT(error_of({}, "999"), HasSubstr("CPM_DOMAIN_ID"));
    EXPECT_THAT(error_of({"--simulated_time=maybe"}), HasSubstr("--simulated_time: 'maybe'"));
    EXPECT_THAT(error_of({"--dds_shared_memory=udp"}), HasSubstr("--dds_shared_memory: 'udp' is not a boolean"));
    EXPECT_THAT(error_of({"--node_id"}), HasSubstr("--node_id: missing value"));
    EXPECT_THAT(error_of({"--node_id="}), HasSubstr("--node_id: empty value"));
}

TEST(Init, TheLeaseIsTenSecondsUnlessTheFlagOrTheEnvironmentSaysOtherwise)
{
    using std::chrono::milliseconds;
    ::unsetenv("CPM_DDS_LEASE");
    EXPECT_EQ(parse({}).lease, milliseconds(10'000));
    EXPECT_EQ(parse({"--dds_lease", "3s"}).lease, milliseconds(3'000));
    EXPECT_EQ(parse({"--dds_lease=1500ms"}).lease, milliseconds(1'500));
    ::setenv("CPM_DDS_LEASE", "4s", 1);
    EXPECT_EQ(parse({}).lease, milliseconds(4'000));
    EXPECT_EQ(parse({"--dds_lease=2s"}).lease, milliseconds(2'000)) << "the flag wins";
    ::setenv("CPM_DDS_LEASE", "soon", 1);
    EXPECT_THAT(error_of({}), HasSubstr("CPM_DDS_LEASE: 'soon' is not a duration"));
    ::unsetenv("CPM_DDS_LEASE");
    EXPECT_THAT(error_of({"--dds_lease=200ms"}), HasSubstr("--dds_lease: 200ms is outside 1s..1h"));
    EXPECT_THAT(error_of({"--dds_lease=2h"}), HasSubstr("--dds_lease: 2h is outside 1s..1h"));
    bool takes_value = false;
    EXPECT_TRUE(cpm::is_init_flag("--dds_lease", takes_value));
    EXPECT_TRUE(takes_value);
}

TEST(Init, AnInterfaceThisHostDoesNotHaveIsRefusedNamingIt)
{
    EXPECT_NO_THROW(cpm::check_local_interface("127.0.0.1", "--dds_interface"));
    EXPECT_NO_THROW(cpm::check_local_interface("lo", "--dds_interface"));
    try {
        cpm::check_local_interface("10.0.0.1", "--dds_interface");
        ADD_FAILURE() << "10.0.0.1 accepted";
    } catch (const cpm::Error& e) {
        EXPECT_THAT(e.what(), HasSubstr("--dds_interface: '10.0.0.1' is neither an interface nor an IPv4 address of this host"));
        EXPECT_THAT(e.what(), HasSubstr("lo (127.0.0.1)"));
    }
    EXPECT_THROW(cpm::check_local_interface("eth9", "--dds_interface"), cpm::Error);
}

TEST(Init, ACommandLineErrorIsAUsageErrorSoProgramsExitWithTwo)
{
    const char* bad_domain[] = {"/usr/bin/my_node", "--dds_domain", "abc"};
    EXPECT_THROW(cpm::init(3, const_cast<char**>(bad_domain)), cpm::cli::UsageError);
    const char* bad_interface[] = {"/usr/bin/my_node", "--dds_interface=10.0.0.1"};
    EXPECT_THROW(cpm::init(2, const_cast<char**>(bad_interface)), cpm::cli::UsageError);
}

TEST(StampMessage, SetsCreateAndValidAfterStamps)
{
    VehicleState sut;
    cpm::stamp_message(sut, 1000, 60);
    EXPECT_EQ(sut.header().create_stamp().nanoseconds(), 1000u);
    EXPECT_EQ(sut.header().valid_after_stamp().nanoseconds(), 1060u);
}
