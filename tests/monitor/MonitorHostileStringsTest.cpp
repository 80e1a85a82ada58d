// The monitor's page against strings from the DDS domain that are HTML: any participant may
// publish fsmStatus, log or historyStatus, and the page that holds the stop buttons must show what
// they say as text and run none of it. A real monitor, real DDS samples, Debian's chromium.
#include <cpm/Participant.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/monitor/Monitor.hpp>
#include <cpm/stamp_message.hpp>
#include <cpm/topics.hpp>

#include <FsmStatus.h>
#include <HistoryStatus.h>
#include <Log.h>
#include <VehicleState.h>

#include <cpm_test/Browser.hpp>
#include <cpm_test/Isolation.hpp>

#include <gtest/gtest.h>

using namespace std::chrono_literals;
namespace t = cpm::topics;

namespace {

/// Each sets window.pwned to its own number when a browser parses it as HTML.
std::string hostile(int n)
{
    return "<img src=x onerror=\"window.pwned=" + std::to_string(n) + "\"><script>window.pwned=" + std::to_string(n) + "</script>";
}

}  // namespace

TEST(MonitorPage, StringsFromTheDomainAreShownAsTextAndRunNoScript)
{
    cpm_test::test_domain_id();
    cpm::Participant participant(cpm::ParticipantOptions::from_init());
    cpm::monitor::MonitorOptions options;
    options.port = 0;
    cpm::monitor::Monitor sut(participant, options);

    cpm::Writer<VehicleState> states(participant, t::vehicle_state.name, t::vehicle_state.writer);
    cpm::Writer<FsmStatus> fsm(participant, t::fsm_status.name, t::fsm_status.writer);
    cpm::Writer<Log> log(participant, t::log.name, t::log.writer);
    cpm::Writer<HistoryStatus> history(participant, t::history_status.name, t::history_status.writer);
    auto publish = [&] {
        const uint64_t now = cpm::get_time_ns();
        VehicleState s;
        s.vehicle_id(9);
        s.pose().x(0.5);
        s.speed(0.3);
        cpm::stamp_message(s, now, 0);
        (void)states.write(s);
        FsmStatus f;
        f.vehicle_id(9);
        f.state_type(hostile(1));
        f.entered_ns(now);
        cpm::stamp_message(f, now, 0);
        (void)fsm.write(f);
        Log l;
        l.id(hostile(2));
        l.content(hostile(3));
        l.log_level(1);
        l.stamp().nanoseconds(now);
        (void)log.write(l);
        HistoryStatus h;
        cpm::stamp_message(h, now, 0);
        HistoryTopicStatus topic;
        topic.topic(hostile(4));
        topic.rate_hz(1.0);
        h.topics().push_back(topic);
        (void)history.write(h);
    };

    cpm_test::Browser browser;
    browser.open("http://127.0.0.1:" + std::to_string(sut.port()) + "/");
    const std::string shown = "document.getElementById('panels').textContent.includes('window.pwned=1') && "
                              "document.getElementById('log').textContent.includes('window.pwned=3') && "
                              "document.getElementById('topics').textContent.includes('window.pwned=4')";
    bool seen = false;
    for (int i = 0; i < 100 && !seen; ++i) {  // samples until the page shows them all, at most 10 s
        publish();
        seen = browser.wait_for(shown, 100ms);
    }
    ASSERT_TRUE(seen) << "the page shows the strings: " << browser.eval("document.body.innerText").dump();

    EXPECT_TRUE(browser.eval("document.querySelector('.panel [data-field=\"state\"]').textContent.startsWith(" +
                             nlohmann::json(hostile(1)).dump() + ")"))
        << "the car's state is the string as sent: " << browser.eval("document.querySelector('.panel').innerText").dump();
    EXPECT_TRUE(browser.eval("document.getElementById('log').textContent.includes(" + nlohmann::json(hostile(2)).dump() + ")"))
        << "the log line's sender as sent";
    EXPECT_TRUE(browser.eval("[...document.querySelectorAll('#cars text, .label')].some(e => e.textContent.includes('window.pwned=1'))"))
        << "the car's label on the map";
    EXPECT_EQ(browser.eval("document.querySelectorAll('#panels img, #panels script, #log img, #log script, "
                           "#topics img, #topics script, #map img').length"),
              0)
        << "no element was made from a string";
    std::this_thread::sleep_for(300ms);  // an image's error handler runs once its load fails
    EXPECT_EQ(browser.eval("typeof window.pwned"), "undefined") << "script " << browser.eval("String(window.pwned)") << " ran";
}
