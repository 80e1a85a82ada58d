#include <cpm/Error.hpp>
#include <cpm/Realtime.hpp>
#include <cpm/init.hpp>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <pthread.h>
#include <sched.h>

#include <thread>

using ::testing::HasSubstr;

namespace {

cpm::InitSettings parse_flags(std::vector<const char*> args)
{
    args.insert(args.begin(), "/usr/bin/car_node");
    return cpm::parse_init_settings(static_cast<int>(args.size()), args.data(), nullptr);
}

std::pair<int, int> policy_of_this_thread()
{
    int policy = -1;
    sched_param param{};
    pthread_getschedparam(pthread_self(), &policy, &param);
    return {policy, param.sched_priority};
}

}  // namespace

TEST(Realtime, TheFlagStandsAloneOrNamesItsModeAndAWrongModeIsNamed)
{
    EXPECT_EQ(parse_flags({}).realtime, cpm::Realtime::off);
    EXPECT_EQ(parse_flags({"--realtime"}).realtime, cpm::Realtime::on);
    EXPECT_EQ(parse_flags({"--realtime=required"}).realtime, cpm::Realtime::required);
    EXPECT_EQ(parse_flags({"--realtime", "--realtime=off"}).realtime, cpm::Realtime::off);
    // --realtime takes no separate value: the next word is the program's own.
    EXPECT_EQ(parse_flags({"--realtime", "required"}).realtime, cpm::Realtime::on);
    bool takes_value = true;
    EXPECT_TRUE(cpm::is_init_flag("--realtime", takes_value));
    EXPECT_FALSE(takes_value);
    try {
        parse_flags({"--realtime=maybe"});
        FAIL() << "a wrong mode was accepted";
    } catch (const cpm::Error& e) {
        EXPECT_THAT(e.what(), HasSubstr("--realtime"));
        EXPECT_THAT(e.what(), HasSubstr("'maybe'"));
        EXPECT_THAT(e.what(), HasSubstr("required"));
    }
}

TEST(Realtime, AThreadRunsFifoAtItsPriorityWhileTheScopeLivesThenAsBefore)
{
    std::thread([] {
        const auto before = policy_of_this_thread();
        ASSERT_EQ(before.first, SCHED_OTHER);
        const std::string missing = cpm::realtime_missing(cpm::realtime_priority::timer);
        {
            const cpm::RealtimeThread off(cpm::Realtime::off, cpm::realtime_priority::timer, "test");
            EXPECT_FALSE(off.active());
            EXPECT_EQ(policy_of_this_thread(), before);
        }
        {
            const cpm::RealtimeThread on(cpm::Realtime::on, cpm::realtime_priority::timer, "test");
            if (missing.empty()) {
                EXPECT_TRUE(on.active());
                EXPECT_EQ(policy_of_this_thread(), std::make_pair(SCHED_FIFO, cpm::realtime_priority::timer));
            } else {
                // Not permitted here: it runs on as it was and says why.
                EXPECT_FALSE(on.active()) << missing;
                EXPECT_EQ(policy_of_this_thread(), before);
            }
        }
        EXPECT_EQ(policy_of_this_thread(), before) << "the old policy came back";
    }).join();
}

TEST(Realtime, TheMissingPrivilegeIsSaidWithHowToGrantIt)
{
    // Priority 99 under a limit of 0 (a lab user's default) is refused unless the process may
    // raise any priority (root, CAP_SYS_NICE).
    std::thread([] {
        if (cpm::realtime_missing(99).empty()) {
            const cpm::RealtimeThread required(cpm::Realtime::required, 99, "test");
            EXPECT_TRUE(required.active());
            return;
        }
        try {
            const cpm::RealtimeThread required(cpm::Realtime::required, 99, "serial loop");
            FAIL() << "required real time without the privilege did not throw";
        } catch (const cpm::Error& e) {
            EXPECT_THAT(e.what(), HasSubstr("serial loop"));
            EXPECT_THAT(e.what(), HasSubstr("SCHED_FIFO priority 99"));
        }
    }).join();
}
