// The `cpm` command as a user meets it: --help and --version, every command-line error with exit
// code 2 and one prefix, and output that cannot be written is an error.
#include <cpm_test/Isolation.hpp>
#include <cpm_test/Process.hpp>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

using namespace std::chrono_literals;
using ::testing::HasSubstr;
using ::testing::Not;
using cpm_test::Process;

namespace {

Process cpm(std::vector<std::string> args)
{
    args.insert(args.begin(), cpm_test::built_program("cpm"));
    return Process(args);
}

TEST(CpmCommand, AnswersVersionAndHelpForEveryGroup)
{
    cpm_test::test_domain_id();
    auto version = cpm({"--version"});
    EXPECT_EQ(version.wait(10s), 0);
    EXPECT_THAT(version.output(), HasSubstr("cpm 0."));
    EXPECT_THAT(version.output(), HasSubstr("Fast DDS 2."));
    for (const char* group : {"lab", "topic", "param", "fsm", "vehicle"}) {
        auto help = cpm({group, "--help"});
        EXPECT_EQ(help.wait(10s), 0) << group << help.errors();
        EXPECT_THAT(help.output(), HasSubstr(std::string("cpm ") + group + " VERB")) << group;
    }
    auto top = cpm({"--help"});
    EXPECT_EQ(top.wait(10s), 0);
    EXPECT_THAT(top.output(), HasSubstr("fsm render"));
    auto history = cpm({"history", "at", "--help"});
    EXPECT_EQ(history.wait(10s), 0);
    EXPECT_THAT(history.output(), HasSubstr("usage: cpm history"));
}

TEST(CpmCommand, CommandLineErrorsExitWithTwoAndNameWhatIsWrongOnce)
{
    cpm_test::test_domain_id();
    auto domain = cpm({"dump", "--dds_domain", "abc"});
    EXPECT_EQ(domain.wait(10s), 2);
    EXPECT_THAT(domain.errors(), HasSubstr("cpm: --dds_domain: 'abc' is not a whole number"));
    auto domain_first = cpm({"--dds_domain", "abc", "dump"});
    EXPECT_EQ(domain_first.wait(10s), 2);
    EXPECT_THAT(domain_first.errors(), HasSubstr("--dds_domain: 'abc'"));
    auto interface = cpm({"dump", "--dds_interface", "10.0.0.1"});
    EXPECT_EQ(interface.wait(10s), 2);
    EXPECT_THAT(interface.errors(), HasSubstr("'10.0.0.1' is neither an interface nor an IPv4 address of this host"));
    auto missing = cpm({"history", "at", "--topic", "--key", "1"});
    EXPECT_EQ(missing.wait(10s), 2);
    EXPECT_EQ(missing.errors(), "cpm history at: --topic needs a value\n");  // one prefix, not "cpm: cpm history at:"
    auto unknown = cpm({"history", "nope"});
    EXPECT_EQ(unknown.wait(10s), 2);
    EXPECT_THAT(unknown.errors(), HasSubstr("unknown command 'history nope'"));
    auto group_only = cpm({"fsm"});
    EXPECT_EQ(group_only.wait(10s), 2);
    EXPECT_THAT(group_only.errors(), HasSubstr("fsm check"));
}

TEST(CpmCommand, OutputThatCannotBeWrittenIsAnError)
{
    cpm_test::test_domain_id();
    Process full({"/bin/sh", "-c", cpm_test::built_program("cpm") + " fsm check " + CPM_SOURCE_DIR "/scenarios/fsm/corridor.json > /dev/full"});
    EXPECT_EQ(full.wait(10s), 1);
    EXPECT_THAT(full.errors(), HasSubstr("cpm: cannot write the output: No space left on device"));
    auto fine = cpm({"fsm", "check", CPM_SOURCE_DIR "/scenarios/fsm/corridor.json"});
    EXPECT_EQ(fine.wait(10s), 0);
    EXPECT_THAT(fine.errors(), Not(HasSubstr("cannot write")));
}

}  // namespace
