// cpm monitor's server in this process, over real DDS and real HTTP (cpp-httplib's client and
// raw sockets): /api/state against the samples written, bad requests answered 400/403/404, a
// StopRequest sent only when allowed, a port in use named, ten watchers at once, and a watcher
// that stops reading dropped without slowing anyone else.
#include <cpm/Error.hpp>
#include <cpm/Participant.hpp>
#include <cpm/Reader.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/monitor/Monitor.hpp>
#include <cpm/stamp_message.hpp>
#include <cpm/topics.hpp>

#include <Bookmark.h>
#include <StopRequest.h>

#include <cpm_test/Isolation.hpp>

#include <gtest/gtest.h>
#include <httplib.h>

#include <arpa/inet.h>
#include <atomic>
#include <cstdio>
#include <fstream>
#include <regex>
#include <netinet/in.h>
#include <sys/socket.h>
#include <thread>
#include <unistd.h>

using namespace std::chrono_literals;
using cpm_test::wait_until;
namespace t = cpm::topics;

namespace {

class MonitorServer : public ::testing::Test
{
protected:
    void SetUp() override { cpm_test::test_domain_id(); }

    std::unique_ptr<cpm::monitor::Monitor> start(cpm::monitor::MonitorOptions o = {})
    {
        o.port = o.port == 8080 ? 0 : o.port;  // a free port unless the test names one
        return std::make_unique<cpm::monitor::Monitor>(participant(), o);
    }
    cpm::Participant& participant()
    {
        if (!participant_) participant_ = std::make_unique<cpm::Participant>(cpm::ParticipantOptions::from_init());
        return *participant_;
    }
    VehicleState car_state(uint8_t id, double x, double y, double speed)
    {
        VehicleState s;
        s.vehicle_id(id);
        s.pose().x(x);
        s.pose().y(y);
        s.pose().yaw(0.1 * id);
        s.speed(speed);
        cpm::stamp_message(s, cpm::get_time_ns(), 0);
        return s;
    }

private:
    std::unique_ptr<cpm::Participant> participant_;
};

nlohmann::json get_json(httplib::Client& c, const std::string& path, int* status = nullptr)
{
    auto r = c.Get(path.c_str());
    if (!r) return nullptr;
    if (status) *status = r->status;
    return nlohmann::json::parse(r->body, nullptr, false);
}

const nlohmann::json* find_car(const nlohmann::json& state, int id)
{
    if (!state.is_object() || !state.contains("vehicles")) return nullptr;
    for (const auto& v : state["vehicles"]) {
        if (v["id"] == id) return &v;
    }
    return nullptr;
}

/// A TCP connection to the monitor with `text` sent on it (and a receive buffer of `receive_buffer`
/// bytes when given), or -1.
int send_raw(int port, const std::string& text, int receive_buffer = 0)
{
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    if (receive_buffer > 0) ::setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &receive_buffer, sizeof receive_buffer);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(uint16_t(port));
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 || ::write(fd, text.data(), text.size()) != ssize_t(text.size())) {
        ::close(fd);
        return -1;
    }
    return fd;
}

/// Resident memory of this process, in bytes.
size_t rss_bytes()
{
    std::ifstream statm("/proc/self/statm");
    size_t pages = 0, resident = 0;
    statm >> pages >> resident;
    return resident * size_t(::sysconf(_SC_PAGESIZE));
}

}  // namespace

TEST_F(MonitorServer, ApiStateMatchesTheSamplesOnTheDomain)
{
    auto monitor = start();
    cpm::Writer<VehicleState> states(participant(), t::vehicle_state.name, t::vehicle_state.writer);
    cpm::Writer<VehicleObservation> seen(participant(), t::vehicle_observation.name, t::vehicle_observation.writer);
    httplib::Client http("127.0.0.1", monitor->port());
    VehicleState written = car_state(5, 1.25, -0.5, 0.42);
    ASSERT_TRUE(wait_until(
        [&] {
            written = car_state(5, 1.25, -0.5, 0.42);
            (void)states.write(written);
            const auto now = get_json(http, "/api/state");
            const auto* v = find_car(now, 5);
            return v && (*v)["state_stamp_ns"] == written.header().create_stamp().nanoseconds();
        },
        10s, 50ms))
        << "the monitor shows the newest VehicleState written";
    auto state = get_json(http, "/api/state");
    const auto* v = find_car(state, 5);
    ASSERT_TRUE(v);
    EXPECT_DOUBLE_EQ((*v)["x"], 1.25);
    EXPECT_DOUBLE_EQ((*v)["y"], -0.5);
    EXPECT_DOUBLE_EQ((*v)["speed"], 0.42);
    EXPECT_EQ((*v)["pose_from"], "vehicleState");
    EXPECT_EQ(state["source"], "live");
    EXPECT_EQ(state["allow_stop"], false);
    EXPECT_TRUE(state["t_ns"].is_number_unsigned());

    VehicleObservation o;
    o.vehicle_id(5);
    o.pose().x(1.3);
    o.pose().y(-0.45);
    cpm::stamp_message(o, cpm::get_time_ns(), 0);
    ASSERT_TRUE(wait_until(
        [&] {
            (void)seen.write(o);
            const auto now = get_json(http, "/api/state");
            const auto* w = find_car(now, 5);
            return w && (*w)["pose_from"] == "vehicleObservation";
        },
        10s, 50ms));
    v = find_car(state = get_json(http, "/api/state"), 5);
    EXPECT_DOUBLE_EQ((*v)["x"], 1.3);
    EXPECT_DOUBLE_EQ((*v)["y"], -0.45);
    bool listed = false;
    for (const auto& topic : state["topics"]) listed = listed || topic["name"] == "vehicleState";
    EXPECT_TRUE(listed) << state["topics"].dump();

    // The page and its script are served from the monitor itself.
    auto page = http.Get("/");
    ASSERT_TRUE(page);
    EXPECT_EQ(page->status, 200);
    EXPECT_NE(page->body.find("<script src=\"/monitor.js\">"), std::string::npos);
    EXPECT_EQ(page->body.find("http"), std::string::npos) << "nothing fetched from anywhere else";
    auto script = http.Get("/monitor.js");
    ASSERT_TRUE(script);
    EXPECT_EQ(script->status, 200);
    EXPECT_EQ(script->get_header_value("Content-Type").rfind("text/javascript", 0), 0u);
    const std::regex asks(R"re((fetch|EventSource)\(\s*["'`]([^"'`]*))re");
    int fetches = 0;
    for (std::sregex_iterator i(script->body.begin(), script->body.end(), asks), end; i != end; ++i, ++fetches) {
        EXPECT_EQ((*i)[2].str().rfind("/", 0), 0u) << "the script asks only its own server: " << (*i)[0];
    }
    EXPECT_GE(fetches, 4) << "world, plots, stream, stop";
    EXPECT_TRUE(get_json(http, "/api/world").contains("walls"));
}

TEST_F(MonitorServer, BadRequestsAreAnsweredWithWhatIsWrong)
{
    auto monitor = start();
    httplib::Client http("127.0.0.1", monitor->port());
    int status = 0;
    auto body = get_json(http, "/no/such/page", &status);
    EXPECT_EQ(status, 404);
    EXPECT_NE(body["error"].get<std::string>().find("/no/such/page"), std::string::npos) << body.dump();
    body = get_json(http, "/api/state?vehicle=5", &status);
    EXPECT_EQ(status, 400);
    EXPECT_NE(body["error"].get<std::string>().find("'vehicle'"), std::string::npos) << body.dump();
    auto stop = http.Post("/api/stop", R"({"vehicle_id": 5})", "application/json");
    ASSERT_TRUE(stop);
    EXPECT_EQ(stop->status, 403) << "stopping is off unless asked for";
    EXPECT_NE(stop->body.find("--allow-stop"), std::string::npos) << stop->body;
    EXPECT_EQ(monitor->stats().stops_sent, 0u);
    // A path that exists, asked with another method: 405 and what it allows.
    auto wrong = http.Get("/api/stop");
    ASSERT_TRUE(wrong);
    EXPECT_EQ(wrong->status, 405) << wrong->body;
    EXPECT_EQ(wrong->get_header_value("Allow"), "POST");
    wrong = http.Delete("/api/state");
    ASSERT_TRUE(wrong);
    EXPECT_EQ(wrong->status, 405) << wrong->body;
    EXPECT_EQ(wrong->get_header_value("Allow"), "GET");
    EXPECT_NE(wrong->body.find("DELETE /api/state"), std::string::npos) << wrong->body;

    // Not HTTP at all: a 400, and the server goes on serving.
    const int fd = send_raw(monitor->port(), "HELLO THERE\r\n\r\n");
    ASSERT_GE(fd, 0);
    char reply[256] = {};
    ASSERT_GT(::read(fd, reply, sizeof reply - 1), 0);
    ::close(fd);
    EXPECT_EQ(std::string(reply).rfind("HTTP/1.1 400", 0), 0u) << reply;
    EXPECT_EQ(get_json(http, "/api/state", &status)["source"], "live");
    EXPECT_EQ(status, 200);
}

TEST_F(MonitorServer, AStopIsSentOnlyWhenAllowedAndOnlyForAValidCar)
{
    cpm::monitor::MonitorOptions o;
    o.allow_stop = true;
    auto monitor = start(o);
    cpm::Reader<StopRequest> stops(participant(), t::stop_request.name, t::stop_request.reader);
    httplib::Client http("127.0.0.1", monitor->port());
    for (const auto& [body, what] : std::vector<std::pair<std::string, std::string>>{
             {"stop car 5", "not JSON"}, {R"({"vehicle": 5})", "vehicle_id"}, {R"({"vehicle_id": 300})", "$.vehicle_id: 300"},
             {R"({"vehicle_id": "5"})", "vehicle_id"}}) {
        auto r = http.Post("/api/stop", body, "application/json");
        ASSERT_TRUE(r);
        EXPECT_EQ(r->status, 400) << body;
        EXPECT_NE(r->body.find(what), std::string::npos) << body << " → " << r->body;
    }
    EXPECT_EQ(monitor->stats().stops_sent, 0u);
    ASSERT_TRUE(wait_until([&] { return stops.matched_publications() > 0; }, 10s));
    // A car the lab does not have: 404, naming the cars it has.
    cpm::Writer<VehicleState> states(participant(), t::vehicle_state.name, t::vehicle_state.writer);
    ASSERT_TRUE(wait_until([&] {
        (void)states.write(car_state(5, 1, 0, 0));
        return find_car(get_json(http, "/api/state"), 5) != nullptr;
    }, 10s, 50ms));
    auto none = http.Post("/api/stop", R"({"vehicle_id": 99})", "application/json");
    ASSERT_TRUE(none);
    EXPECT_EQ(none->status, 404) << none->body;
    EXPECT_NE(none->body.find("no car 99 in this lab (cars: 5;"), std::string::npos) << none->body;
    EXPECT_EQ(monitor->stats().stops_sent, 0u);
    auto r = http.Post("/api/stop", R"({"vehicle_id": 5})", "application/json");
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 200) << r->body;
    ASSERT_TRUE(wait_until([&] { return stops.get_sample(cpm::get_time_ns()).valid; }, 5s));
    EXPECT_EQ(stops.get_sample(cpm::get_time_ns()).sample.vehicle_id(), 5);
    r = http.Post("/api/stop", R"({"vehicle_id": 0})", "application/json");
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 200);
    EXPECT_NE(r->body.find("every car"), std::string::npos) << r->body;
    EXPECT_EQ(monitor->stats().stops_sent, 2u);
}

TEST_F(MonitorServer, AMarkIsABookmarkFromTheMonitorAndAWrongOneIsNamed)
{
    auto monitor = start();
    httplib::Client http("127.0.0.1", monitor->port());
    // Nobody records bookmarks yet: said, not lost quietly.
    auto unheard = http.Post("/api/mark", R"({"text": "too early"})", "application/json");
    ASSERT_TRUE(unheard);
    EXPECT_EQ(unheard->status, 503) << unheard->body;
    EXPECT_NE(unheard->body.find("nobody records bookmarks"), std::string::npos) << unheard->body;
    cpm::Reader<Bookmark> marks(participant(), t::bookmark.name, t::bookmark.reader);
    for (const auto& [body, what] : std::vector<std::pair<std::string, std::string>>{
             {"lap two", "not JSON"}, {R"({"note": "x"})", "the body must be"}, {R"({"text": "  "})", "$.text: a bookmark needs a text"},
             {R"({"text": ")" + std::string(300, 'x') + R"("})", "$.text: the text is 300 bytes; at most 256"},
             {R"({"text": "two\nlines"})", "$.text: a control character"}}) {
        auto r = http.Post("/api/mark", body, "application/json");
        ASSERT_TRUE(r);
        EXPECT_EQ(r->status, 400) << body;
        EXPECT_NE(r->body.find(what), std::string::npos) << body << " → " << r->body;
    }
    // Another site's page cannot post JSON without asking first: a body not sent as JSON is refused.
    auto plain = http.Post("/api/mark", R"({"text": "from elsewhere"})", "text/plain");
    ASSERT_TRUE(plain);
    EXPECT_EQ(plain->status, 415) << plain->body;
    ASSERT_TRUE(wait_until([&] { return marks.matched_publications() > 0; }, 10s));
    auto r = http.Post("/api/mark", R"({"text": "car 5 <b>touched</b> the wall"})", "application/json");
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 200) << r->body;
    ASSERT_TRUE(wait_until([&] { return marks.get_sample(cpm::get_time_ns()).valid; }, 5s));
    const auto got = marks.get_sample(cpm::get_time_ns()).sample;
    EXPECT_EQ(got.text(), "car 5 <b>touched</b> the wall");
    EXPECT_EQ(got.source(), "monitor");
    EXPECT_EQ(http.Get("/api/mark")->status, 405);
}

TEST_F(MonitorServer, APortInUseIsNamedAtStart)
{
    auto first = start();
    cpm::monitor::MonitorOptions o;
    o.port = first->port();
    try {
        start(o);
        FAIL() << "a second monitor on the same port must not start";
    } catch (const cpm::Error& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find("127.0.0.1:" + std::to_string(first->port())), std::string::npos) << what;
        EXPECT_NE(what.find("in use"), std::string::npos) << what;
    }
    o.port = 0;
    o.world = "/no/such/world.json";
    EXPECT_THROW(start(o), std::exception) << "a world file that cannot be read";
}

TEST_F(MonitorServer, TenWatchersAtOnceEachGetTheStream)
{
    auto monitor = start();
    cpm::Writer<VehicleState> states(participant(), t::vehicle_state.name, t::vehicle_state.writer);
    std::atomic<bool> done{false};
    std::vector<std::atomic<int>> events(10);
    std::vector<std::thread> watchers;
    for (int i = 0; i < 10; ++i) {
        watchers.emplace_back([&, i] {
            httplib::Client http("127.0.0.1", monitor->port());
            http.Get("/api/stream", [&](const char* data, size_t n) {
                const std::string chunk(data, n);
                for (size_t p = chunk.find("data: "); p != std::string::npos; p = chunk.find("data: ", p + 1)) ++events[i];
                return !done.load();
            });
        });
    }
    ASSERT_TRUE(wait_until([&] { return monitor->stats().watchers == 10; }, 10s)) << monitor->stats().watchers;
    const auto end = std::chrono::steady_clock::now() + 3s;
    while (std::chrono::steady_clock::now() < end) {
        (void)states.write(car_state(1, 0, 0, 0.3));
        std::this_thread::sleep_for(20ms);
    }
    done = true;
    for (auto& w : watchers) w.join();
    for (int i = 0; i < 10; ++i) EXPECT_GE(events[i].load(), 20) << "watcher " << i << ": a snapshot at least every 150 ms while data comes at 50 Hz";
    EXPECT_TRUE(wait_until([&] { return monitor->stats().watchers == 0; }, 5s)) << "each watcher that left is let go";
}

TEST_F(MonitorServer, AWatcherThatStopsReadingIsDroppedWithoutSlowingTheOthers)
{
    cpm::monitor::MonitorOptions o;
    o.write_timeout = 1s;
    auto monitor = start(o);
    cpm::Writer<VehicleState> states(participant(), t::vehicle_state.name, t::vehicle_state.writer);
    // The stuck watcher: asks for the stream with a tiny receive buffer and never reads.
    const int stuck = send_raw(monitor->port(), "GET /api/stream HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n", 2048);
    ASSERT_GE(stuck, 0);
    std::atomic<bool> done{false};
    std::atomic<int> events{0};
    std::thread reader([&] {
        httplib::Client http("127.0.0.1", monitor->port());
        http.Get("/api/stream", [&](const char* data, size_t n) {
            const std::string chunk(data, n);
            for (size_t p = chunk.find("data: "); p != std::string::npos; p = chunk.find("data: ", p + 1)) ++events;
            return !done.load();
        });
    });
    ASSERT_TRUE(wait_until([&] { return monitor->stats().watchers == 2; }, 10s));
    const size_t rss_before = rss_bytes();
    // 20 cars at 50 Hz for 8 s: snapshots of a few kB, 50 a second.
    bool dropped = false;
    const auto end = std::chrono::steady_clock::now() + 8s;
    while (std::chrono::steady_clock::now() < end) {
        for (uint8_t id = 1; id <= 20; ++id) (void)states.write(car_state(id, id * 0.5, 1.0, 0.3));
        dropped = dropped || monitor->stats().watchers == 1;
        std::this_thread::sleep_for(20ms);
    }
    const int got = events.load();
    done = true;
    reader.join();
    ::close(stuck);
    EXPECT_TRUE(dropped) << "the watcher that stopped reading is let go after the write timeout";
    EXPECT_GE(got, 8 * 15) << "the reading watcher kept getting snapshots (most of 50 a second)";
#ifndef __SANITIZE_ADDRESS__
    EXPECT_LT(rss_bytes(), rss_before + 32u * 1024 * 1024) << "no queue grows for the stuck watcher";
#else
    // AddressSanitizer holds up to 256 MB of freed memory back (its quarantine): the growth of the
    // resident set says nothing there. Judged in every other build.
    std::printf("AddressSanitizer build: the memory growth (%.1f MiB) is not judged\n",
                (double(rss_bytes()) - double(rss_before)) / (1024.0 * 1024.0));
#endif
}
