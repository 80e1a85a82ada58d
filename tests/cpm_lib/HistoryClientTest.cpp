// cpm::HistoryClient on a domain where no history service runs: every call throws cpm::Error
// saying so, after its reply timeout, and never returns a made-up answer.
#include <cpm/HistoryClient.hpp>

#include <cpm_test/Dds.hpp>
#include <cpm_test/Isolation.hpp>

#include <VehicleState.h>

#include <gtest/gtest.h>

using namespace std::chrono_literals;

TEST(HistoryClient, WithNoServiceEveryCallThrowsNamingWhatIsMissing)
{
    cpm::Participant participant(cpm_test::isolated_options());
    cpm::HistoryClient client(participant, 300ms);
    try {
        (void)client.at<VehicleState>("vehicleState", 3, 1000);
        FAIL() << "an answer without a service";
    } catch (const cpm::Error& e) {
        EXPECT_STREQ(e.what(), "history: no history service answers on this domain (is cpm_history running?)");
    }
    EXPECT_THROW((void)client.request(cpm::HistoryClient::make(cpm::history::Kind::list, "", "")), cpm::Error);
    EXPECT_THROW((void)client.latest("vehicleState", "3"), cpm::Error);
}
