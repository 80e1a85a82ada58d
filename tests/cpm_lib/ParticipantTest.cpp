// What a participant sends and where: this host only, unless told otherwise.
#include <cpm/Error.hpp>
#include <cpm/Participant.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/Writer.hpp>
#include <cpm_test/Dds.hpp>
#include <cpm_test/Isolation.hpp>
#include <cpm_test/Process.hpp>

#include <VehicleState.h>

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/domain/DomainParticipantListener.hpp>
#include <fastdds/dds/log/Log.hpp>
#include <fastrtps/utils/IPLocator.h>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <mutex>
#include <unistd.h>

using namespace std::chrono_literals;
using ::testing::HasSubstr;
namespace fdds = eprosima::fastdds::dds;
namespace rtps = eprosima::fastrtps::rtps;

namespace {

// Records the locators every discovered participant announces.
class LocatorProbe : public fdds::DomainParticipantListener
{
public:
    void on_participant_discovery(fdds::DomainParticipant*, rtps::ParticipantDiscoveryInfo&& info) override
    {
        if (info.status != rtps::ParticipantDiscoveryInfo::DISCOVERED_PARTICIPANT) return;
        std::lock_guard<std::mutex> lock(mutex);
        const auto& data = info.info;
        Seen& seen = by_name[data.m_participantName.to_string()];
        for (const auto& l : data.metatraffic_locators.unicast) seen.unicast.push_back(l);
        for (const auto& l : data.default_locators.unicast) seen.unicast.push_back(l);
        for (const auto& l : data.metatraffic_locators.multicast) seen.multicast.push_back(l);
        for (const auto& l : data.default_locators.multicast) seen.multicast.push_back(l);
    }
    struct Seen
    {
        std::vector<rtps::Locator_t> unicast, multicast;
    };
    std::mutex mutex;
    std::map<std::string, Seen> by_name;
};

std::string describe(const rtps::Locator_t& l)
{
    std::ostringstream out;
    out << l;
    return out.str();
}

}  // namespace

TEST(Participant, DefaultParticipantAnnouncesOnlyLoopbackAndSharedMemory)
{
    cpm::ParticipantOptions options = cpm_test::isolated_options();  // also sets CPM_DOMAIN_ID
    cpm::Participant& sut = cpm::Participant::default_participant();
    ASSERT_EQ(sut.domain_id(), options.domain_id);
    const std::string sut_name = sut.native()->get_qos().name().to_string();

    // A probe participant with the same transport settings sees what sut announces.
    LocatorProbe probe;
    auto qos = sut.native()->get_qos();
    qos.name("locator_probe");
    auto* factory = fdds::DomainParticipantFactory::get_instance();
    fdds::DomainParticipant* probe_participant = factory->create_participant(
        options.domain_id, qos, &probe, fdds::StatusMask::none());
    ASSERT_NE(probe_participant, nullptr);

    const bool seen = cpm_test::wait_until([&] {
        std::lock_guard<std::mutex> lock(probe.mutex);
        return probe.by_name.count(sut_name) > 0;
    });
    factory->delete_participant(probe_participant);

    ASSERT_TRUE(seen) << "the probe never discovered the default participant";
    const auto& announced = probe.by_name[sut_name];
    EXPECT_TRUE(announced.multicast.empty()) << "announces multicast: " << describe(announced.multicast.front());
    ASSERT_FALSE(announced.unicast.empty());
    for (const auto& l : announced.unicast) {
        const bool shm = l.kind == LOCATOR_KIND_SHM;
        const bool loopback = l.kind == LOCATOR_KIND_UDPv4 && rtps::IPLocator::toIPv4string(l) == "127.0.0.1";
        EXPECT_TRUE(shm || loopback) << "announces a locator beyond this host: " << describe(l);
    }
}

TEST(Participant, APeerKilledIsDroppedWhenItsShorterLeaseRunsOut)
{
    // A participant's lease (--dds_lease) is how long the others wait for it once it falls
    // silent; the default is 10 s. A reader process with a 1.5 s lease, killed with SIGKILL,
    // is dropped within a few seconds.
    std::atomic<std::chrono::steady_clock::time_point> dropped_at{};
    cpm::ParticipantOptions options = cpm_test::isolated_options();
    options.on_discovery = [&](const cpm::DiscoveryEvent& e) {
        if (e.kind == cpm::DiscoveryEvent::Kind::participant_gone && e.participant_name == "reliable_reader") {
            dropped_at.store(std::chrono::steady_clock::now());
        }
    };
    const std::string topic = cpm_test::unique_topic("vehicleState");
    cpm::Participant participant(options);
    cpm::Writer<VehicleState> writer(participant, topic, {.reliable = true});
    cpm_test::Process reader({cpm_test::built_program("reliable_reader"), topic, "--dds_lease", "1500ms"});
    ASSERT_TRUE(writer.wait_for_matched(1, 10000ms));
    const auto killed = std::chrono::steady_clock::now();
    reader.kill(SIGKILL);
    ASSERT_TRUE(cpm_test::wait_until([&] { return dropped_at.load() > killed; }, 10000ms))
        << "not dropped within the default lease";
    const double after = std::chrono::duration<double>(dropped_at.load() - killed).count();
    std::printf("dropped %.2f s after the kill\n", after);
    EXPECT_LT(after, 5.0) << "a 1.5 s lease";
    EXPECT_TRUE(cpm_test::wait_until([&] { return writer.matched_subscriptions() == 0; }, 2000ms)) << "its reader still matched";
}

TEST(Participant, FastDdsLogsGoToStderrNeverIntoTheProgramsStdout)
{
    // A program's stdout is its output (`cpm topic echo --json`, firmware_sim's "device: …"
    // line that `cpm vehicle sim` reads); Fast DDS prints its own log to stdout by default.
    cpm::Participant participant(cpm_test::isolated_options());
    std::fflush(stdout);
    std::fflush(stderr);
    FILE* out = std::tmpfile();
    FILE* err = std::tmpfile();
    const int saved_out = ::dup(1), saved_err = ::dup(2);
    ::dup2(::fileno(out), 1);
    ::dup2(::fileno(err), 2);
    using FastDdsLog = eprosima::fastdds::dds::Log;  // (the IDL's Log type is ::Log)
    FastDdsLog::QueueLog("a marker error 4711", FastDdsLog::Context{__FILE__, __LINE__, __func__, "CPM_TEST"},
                         FastDdsLog::Kind::Error);
    FastDdsLog::Flush();
    std::fflush(stdout);
    std::fflush(stderr);
    ::dup2(saved_out, 1);
    ::dup2(saved_err, 2);
    ::close(saved_out);
    ::close(saved_err);
    auto text = [](FILE* f) {
        std::string s;
        std::rewind(f);
        for (int c; (c = std::fgetc(f)) != EOF;) s += char(c);
        std::fclose(f);
        return s;
    };
    const std::string on_stdout = text(out), on_stderr = text(err);
    EXPECT_EQ(on_stdout.find("4711"), std::string::npos) << "stdout: " << on_stdout;
    EXPECT_NE(on_stderr.find("a marker error 4711"), std::string::npos) << "stderr: " << on_stderr;
}

TEST(Participant, ALeaseOutsideOneSecondToAnHourIsRefused)
{
    cpm::ParticipantOptions options = cpm_test::isolated_options();
    options.lease = std::chrono::milliseconds(999);
    try {
        cpm::Participant sut(options);
        FAIL() << "no error";
    } catch (const cpm::Error& e) {
        EXPECT_THAT(e.what(), HasSubstr("participant option lease: 999ms is outside 1s..1h"));
    }
    options.lease = std::chrono::milliseconds(2000);
    cpm::Participant sut(options);
    const auto& discovery = sut.native()->get_qos().wire_protocol().builtin.discovery_config;
    EXPECT_EQ(discovery.leaseDuration.seconds, 2);
    EXPECT_LE(discovery.leaseDuration_announcementperiod.to_ns() * 3, discovery.leaseDuration.to_ns())
        << "announced at least three times per lease";
}

TEST(Participant, DomainAbove232IsRejected)
{
    cpm::ParticipantOptions options;
    options.domain_id = 233;
    try {
        cpm::Participant sut(options);
        FAIL() << "no error";
    } catch (const cpm::Error& e) {
        EXPECT_THAT(e.what(), HasSubstr("233"));
    }
}

TEST(Participant, MalformedPeerIsAnErrorNamingIt)
{
    cpm::ParticipantOptions options = cpm_test::isolated_options();
    options.initial_peers = {"not-an-address:7400"};
    try {
        cpm::Participant sut(options);
        FAIL() << "no error";
    } catch (const cpm::Error& e) {
        EXPECT_THAT(e.what(), HasSubstr("not-an-address"));
    }
}

TEST(Participant, MovedParticipantKeepsWorking)
{
    cpm::Participant original(cpm_test::isolated_options());
    cpm::Participant sut(std::move(original));
    cpm::Participant other(cpm_test::isolated_options());
    const std::string topic = cpm_test::unique_topic("vehicleState");

    cpm::Writer<VehicleState> writer(sut, topic);
    cpm::ReaderAbstract<VehicleState> reader(other, topic);

    EXPECT_TRUE(writer.wait_for_matched(1, 5000ms));
}

TEST(Participant, ReadersAndWritersMeetThroughADiscoveryServer)
{
    // A real Fast DDS discovery server on loopback; both participants are its clients.
    const int port = 20000 + cpm_test::test_domain_id() * 10;
    cpm_test::Process server({"/usr/bin/fast-discovery-server", "-i", "0", "-l", "127.0.0.1", "-p",
                              std::to_string(port)});
    cpm::ParticipantOptions options = cpm_test::isolated_options();
    options.discovery_server = "127.0.0.1:" + std::to_string(port);
    options.interfaces = {"127.0.0.1"};
    cpm::Participant a(options), b(options);
    const std::string topic = cpm_test::unique_topic("vehicleState");

    cpm::Writer<VehicleState> writer(a, topic, {.reliable = true});
    cpm::ReaderAbstract<VehicleState> reader(b, topic, {.reliable = true});

    ASSERT_TRUE(writer.wait_for_matched(1, 10000ms)) << "no match through the discovery server";
    ASSERT_TRUE(reader.wait_for_matched(1, 5000ms));  // both directions, or a write may be skipped
    ASSERT_TRUE(writer.write(cpm_test::vehicle_state(5, 1, 1)));
    ASSERT_TRUE(reader.wait_for_data(5000ms));
    EXPECT_EQ(reader.take().at(0).vehicle_id(), 5);
}
