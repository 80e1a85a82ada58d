// cpm::LogThrottle: a repeated message goes through once per interval, with the count held back.
#include <cpm/LogThrottle.hpp>

#include <cpm_test/Dds.hpp>
#include <gtest/gtest.h>

namespace {

using cpm_test::kMs;

TEST(LogThrottle, LetsTheFirstThroughThenOncePerIntervalWithTheCountHeldBack)
{
    cpm::LogThrottle sut(1000 * kMs);
    uint64_t held = 99;
    EXPECT_TRUE(sut.allow(5000 * kMs, held));
    EXPECT_EQ(held, 0u);
    int passed = 0;
    for (uint64_t t = 5020; t < 6000; t += 20) passed += sut.allow(t * kMs, held);  // 49 more within the second
    EXPECT_EQ(passed, 0);
    EXPECT_TRUE(sut.allow(6000 * kMs, held));
    EXPECT_EQ(held, 49u);
    EXPECT_TRUE(sut.allow(7500 * kMs, held));
    EXPECT_EQ(held, 0u);
    EXPECT_EQ(sut.total(), 52u);
}

}  // namespace
