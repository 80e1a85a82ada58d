// A secured lab (cpm security init / add-node) with real processes: a node with a grant is read
// by the nodes allowed to; no participant without the lab's credentials sees or writes anything
// (no credentials, another lab's CA, an expired certificate, permissions signed by the wrong
// key); a node cannot create what its permissions do not grant.
#include <cpm/Participant.hpp>
#include <cpm/HistoryClient.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/Security.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>

#include <cpm_test/Dds.hpp>
#include <cpm_test/Isolation.hpp>
#include <cpm_test/Process.hpp>
#include <cpm_test/TempDir.hpp>
#include <cpm_test/SourceDir.hpp>

#include <FsmStatus.h>
#include <VehicleCommandDirect.h>
#include <VehicleObservation.h>
#include <cpm_topic_types.hpp>

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <VehicleCommandDirectPubSubTypes.h>
#include <VehicleState.h>

#include <gtest/gtest.h>

#include <atomic>
#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <thread>

namespace {

using namespace std::chrono_literals;
using cpm_test::built_program;
using cpm_test::Process;
namespace fs = std::filesystem;

/// Runs a shell command; its exit code.
int shell(const std::string& command) { return std::system((command + " >/dev/null 2>&1").c_str()); }

/// One lab made with cpm's own library: a writer of vehicleState, a viewer of it.
struct Lab
{
    cpm_test::TempDir tmp;
    std::string dir = tmp.file("lab");
    Lab()
    {
        cpm::security::init_lab(dir, 30);
        cpm::security::add_node(dir, "writer", {.publish = {"vehicleState"}, .subscribe = {}});
        cpm::security::add_node(dir, "viewer", {.publish = {}, .subscribe = {"vehicleState"}});
    }
    std::string node(const std::string& name) const { return dir + "/nodes/" + name; }
};

cpm::ParticipantOptions secured(const std::string& node_dir)
{
    auto options = cpm_test::isolated_options();
    options.security = node_dir;
    return options;
}

/// Counts the VehicleState samples a participant receives: the lab's (cars 1..4) and the
/// strangers' (car 99).
struct Counter
{
    cpm::ReaderAbstract<VehicleState> reader;
    int samples = 0, forged = 0;
    explicit Counter(cpm::Participant& p) : reader(p, "vehicleState", {.keep_all = true}) {}
    void poll()
    {
        for (const auto& s : reader.take()) ++(s.vehicle_id() == 99 ? forged : samples);
    }
};

}  // namespace

TEST(Security, CpmSecurityMakesALabWithTwoCasAndRefusesWhatIsWrong)
{
    cpm_test::TempDir tmp;
    const std::string cpm = built_program("cpm"), lab = tmp.file("lab");
    ASSERT_EQ(shell(cpm + " security init " + lab + " --days 30"), 0);
    for (const char* f : {"identity_ca.cert.pem", "identity_ca.key.pem", "permissions_ca.cert.pem", "permissions_ca.key.pem", "governance.p7s"})
        EXPECT_TRUE(fs::exists(lab + "/" + f)) << f;
    Process again({cpm, "security", "init", lab});
    EXPECT_NE(again.wait(10s), 0);
    EXPECT_NE(again.errors().find("already holds a lab"), std::string::npos) << again.errors();

    ASSERT_EQ(shell(cpm + " security add-node " + lab + " viewer --subscribe vehicleState,vehicle*"), 0);
    const std::string node = lab + "/nodes/viewer";
    for (const char* f : {"cert.pem", "key.pem", "permissions.p7s", "identity_ca.cert.pem", "permissions_ca.cert.pem", "governance.p7s"})
        EXPECT_TRUE(fs::exists(node + "/" + f)) << f;
    EXPECT_FALSE(fs::exists(node + "/identity_ca.key.pem")) << "a node's folder must not carry a CA key";
    EXPECT_EQ((fs::status(node + "/key.pem").permissions() & fs::perms::others_read), fs::perms::none);
    // The node's certificate chains to the identity CA and not to the permissions CA, so that it
    // can never sign policy; its permissions verify against the permissions CA.
    EXPECT_EQ(shell("openssl verify -CAfile " + lab + "/identity_ca.cert.pem " + node + "/cert.pem"), 0);
    EXPECT_NE(shell("openssl verify -CAfile " + lab + "/permissions_ca.cert.pem " + node + "/cert.pem"), 0);
    EXPECT_EQ(shell("openssl smime -verify -in " + node + "/permissions.p7s -CAfile " + lab + "/permissions_ca.cert.pem -out /dev/null"), 0);

    for (const auto& [args, message] : std::vector<std::pair<std::vector<std::string>, std::string>>{
             {{"add-node", lab, "viewer"}, "exists already"},
             {{"add-node", lab, "bad name"}, "node name 'bad name'"},
             {{"add-node", tmp.file("nolab"), "x"}, "not a cpm lab's security folder"},
             {{"add-node", lab, "x", "--publish", "vehicle state"}, "topic 'vehicle state'"},
             {{"add-node", lab, "x", "--days", "0"}, "--days"},
             {{"init"}, "DIR"}}) {
        std::vector<std::string> argv{cpm, "security"};
        argv.insert(argv.end(), args.begin(), args.end());
        Process p(argv);
        EXPECT_NE(p.wait(10s), 0) << args[0];
        EXPECT_NE(p.errors().find(message), std::string::npos) << p.errors();
    }
    EXPECT_FALSE(fs::exists(lab + "/nodes/x")) << "a refused node leaves nothing behind";
}

TEST(Security, ASecuredNodeIsReadByTheGrantedAndByNoStranger)
{
    Lab lab;
    cpm_test::TempDir other;
    const std::string other_lab = other.file("lab");
    cpm::security::init_lab(other_lab, 30);
    cpm::security::add_node(other_lab, "viewer", {.publish = {"vehicleState"}, .subscribe = {"vehicleState"}});

    Process writer({built_program("vehicle_state_writer"), "--seconds", "60", "--security", lab.node("writer")});
    cpm::Participant viewer_p(secured(lab.node("viewer")));
    Counter viewer(viewer_p);
    cpm::Participant open_p(cpm_test::isolated_options());
    Counter open(open_p);
    cpm::Participant foreign_p(secured(other_lab + "/nodes/viewer"));
    Counter foreign(foreign_p);
    // Strangers also try to write: a car 99 that must never reach the viewer.
    cpm::Participant open_writer_p(cpm_test::isolated_options());
    cpm::Participant foreign_writer_p(secured(other_lab + "/nodes/viewer"));
    cpm::Writer<VehicleState> open_writer(open_writer_p, "vehicleState");
    cpm::Writer<VehicleState> foreign_writer(foreign_writer_p, "vehicleState");
    auto forge = [&] {
        auto s = cpm_test::vehicle_state(99, cpm::get_time_ns(), 0);
        (void)open_writer.write(s);
        (void)foreign_writer.write(s);
    };

    ASSERT_TRUE(cpm_test::wait_until([&] { viewer.poll(); return viewer.samples > 20; }, 20s)) << writer.errors();
    EXPECT_TRUE(cpm_test::holds_for([&] {
        forge();
        viewer.poll(), open.poll(), foreign.poll();
        return open.samples == 0 && foreign.samples == 0 && viewer.forged == 0;
    }, 3s, 20ms)) << "unsecured saw " << open.samples << ", another lab's node saw " << foreign.samples
                  << ", forged samples read by the viewer: " << viewer.forged;
    // Each stranger's writer found its own kind (the unsecured reader, the other lab's), never
    // the lab's reader; the lab's reader matched the lab's writer alone.
    EXPECT_GT(open.forged + foreign.forged, 0) << "the strangers' own writes reached nobody: the check above proves nothing";
    EXPECT_EQ(viewer.reader.matched_publications(), 1u);
}

TEST(Security, AnExpiredCertificateOrForgedPermissionsAreRefused)
{
    Lab lab;
    // An expired certificate from the right CA: issued normally, then replaced by one that ended
    // yesterday.
    cpm::security::add_node(lab.dir, "old", {.publish = {}, .subscribe = {"vehicleState"}});
    const std::string old = lab.node("old");
    ASSERT_EQ(shell("openssl req -new -key " + old + "/key.pem -subj '/O=cpm lab/CN=old' -out " + old + "/cert.csr && openssl x509 -req -in " +
                    old + "/cert.csr -CA " + lab.dir + "/identity_ca.cert.pem -CAkey " + lab.dir + "/identity_ca.key.pem -CAserial " +
                    lab.dir + "/identity_ca.srl -days -1 -out " + old + "/cert.pem"),
              0);
    // Permissions signed by a key other than the permissions CA's (the identity CA's).
    cpm::security::add_node(lab.dir, "forged", {.publish = {"vehicleState"}, .subscribe = {"vehicleState"}});
    const std::string forged = lab.node("forged");
    ASSERT_EQ(shell("openssl smime -sign -text -in " + forged + "/permissions.xml -out " + forged + "/permissions.p7s -signer " + lab.dir +
                    "/identity_ca.cert.pem -inkey " + lab.dir + "/identity_ca.key.pem"),
              0);

    Process writer({built_program("vehicle_state_writer"), "--seconds", "60", "--security", lab.node("writer")});
    cpm::Participant viewer_p(secured(lab.node("viewer")));
    Counter viewer(viewer_p);
    ASSERT_TRUE(cpm_test::wait_until([&] { viewer.poll(); return viewer.samples > 0; }, 20s)) << writer.errors();
    // Fast DDS checks a participant's own credentials when it is made: neither joins.
    for (const auto& node : {old, forged}) {
        try {
            cpm::Participant p(secured(node));
            ADD_FAILURE() << node << ": a participant was made with these credentials";
        } catch (const cpm::Error& e) {
            EXPECT_NE(std::string(e.what()).find("with the security folder " + node), std::string::npos) << e.what();
        }
    }
    // The same as a process: it says so and ends.
    Process monitor({built_program("vehicle_state_monitor"), "--security", old});
    EXPECT_NE(monitor.wait(20s), 0);
    EXPECT_NE(monitor.errors().find("security folder"), std::string::npos) << monitor.errors();
}

TEST(Security, ANodeCreatesOnlyWhatItsPermissionsGrantAndSaysWhy)
{
    Lab lab;
    cpm::Participant viewer(secured(lab.node("viewer")));
    cpm::ReaderAbstract<VehicleState> allowed(viewer, "vehicleState");
    try {
        cpm::Writer<VehicleCommandDirect> w(viewer, "vehicleCommandDirect");
        ADD_FAILURE() << "a writer the permissions do not grant was made";
    } catch (const cpm::Error& e) {
        const std::string m = e.what();
        EXPECT_NE(m.find("'vehicleCommandDirect'"), std::string::npos) << m;
        EXPECT_NE(m.find("may not publish"), std::string::npos) << m;
        EXPECT_NE(m.find(lab.node("viewer") + "/permissions.xml"), std::string::npos) << m;
    }
    try {
        cpm::ReaderAbstract<VehicleState> shared(viewer, "vehicleState", {.data_sharing = true});
        ADD_FAILURE() << "data sharing on a secured participant was accepted";
    } catch (const cpm::Error& e) {
        EXPECT_NE(std::string(e.what()).find("data_sharing and DDS Security"), std::string::npos) << e.what();
    }
    // Not only cpm's check: Fast DDS itself refuses the writer when cpm is bypassed.
    auto* native = viewer.native();
    eprosima::fastdds::dds::TypeSupport type(cpm::TopicType<VehicleCommandDirect>::make_type_support());
    ASSERT_EQ(type.register_type(native), ReturnCode_t::RETCODE_OK);
    auto* topic = native->create_topic("vehicleCommandDirect", type.get_type_name(), eprosima::fastdds::dds::TOPIC_QOS_DEFAULT);
    ASSERT_NE(topic, nullptr);
    auto* publisher = native->create_publisher(eprosima::fastdds::dds::PUBLISHER_QOS_DEFAULT);
    EXPECT_EQ(publisher->create_datawriter(topic, eprosima::fastdds::dds::DATAWRITER_QOS_DEFAULT), nullptr)
        << "Fast DDS let a node write a topic its permissions do not grant";
    native->delete_publisher(publisher);
    native->delete_topic(topic);
    // The builtin topics every cpm process uses need no grant.
    EXPECT_TRUE(cpm::security::why_not_allowed(cpm::security::node_files(lab.node("viewer")), "log", true).empty());
    EXPECT_TRUE(cpm::security::why_not_allowed(cpm::security::node_files(lab.node("viewer")), "parameter", false).empty());
}

TEST(Security, AMissingSecurityFolderIsNamedByFlagAndByEnvironment)
{
    Process by_flag({built_program("vehicle_state_monitor"), "--security", "/nonexistent/nodes/x"});
    EXPECT_NE(by_flag.wait(10s), 0);
    EXPECT_NE(by_flag.errors().find("/nonexistent/nodes/x: no such folder"), std::string::npos) << by_flag.errors();
    Lab lab;
    fs::remove(lab.node("viewer") + "/key.pem");
    Process by_env({built_program("vehicle_state_monitor")}, {"CPM_SECURITY=" + lab.node("viewer")});
    EXPECT_NE(by_env.wait(10s), 0);
    EXPECT_NE(by_env.errors().find("key.pem is missing"), std::string::npos) << by_env.errors();
}

TEST(Security, TheHistoryGivesEachNodeThePastOfWhatItMaySubscribeOnly)
{
    Lab lab;
    cpm::security::add_node(lab.dir, "history", {.publish = {"historyReply*", "historyStatus"}, .subscribe = {"*"}});
    cpm::security::add_node(lab.dir, "commander", {.publish = {"vehicleCommandDirect"}, .subscribe = {"vehicleCommandDirect"}});
    Process history({built_program("cpm_history"), "--security", lab.node("history")});
    Process writer({built_program("vehicle_state_writer"), "--seconds", "60", "--security", lab.node("writer")});

    // The viewer may subscribe vehicleState: it gets its past, as a library call and from `cpm history`.
    cpm::Participant viewer_p(secured(lab.node("viewer")));
    cpm::HistoryClient viewer(viewer_p, 10s);
    ASSERT_TRUE(cpm_test::wait_until([&] {
        try {
            return viewer.latest("vehicleState", "1").status() == "ok";
        } catch (const cpm::Error&) {
            return false;
        }
    }, 30s)) << history.errors() << writer.errors();
    EXPECT_EQ(viewer.latest("vehicleState", "1").samples().size(), 1u);
    Process cli({built_program("cpm"), "history", "latest", "--topic", "vehicleState", "--key", "2", "--security", lab.node("viewer")});
    EXPECT_EQ(cli.wait(30s), 0) << cli.errors();
    EXPECT_NE(cli.output().find("vehicleState/2"), std::string::npos) << cli.output();

    // The commander may not: asking for it is refused before anything is sent, naming the topic.
    cpm::Participant commander_p(secured(lab.node("commander")));
    cpm::HistoryClient commander(commander_p, 10s);
    try {
        (void)commander.latest("vehicleState", "1");
        ADD_FAILURE() << "the commander got the past of a topic it may not subscribe";
    } catch (const cpm::Error& e) {
        EXPECT_NE(std::string(e.what()).find("the past of 'vehicleState' is not for this node"), std::string::npos) << e.what();
    }
    // Nor around it: by object id alone, or naming a topic it may read for an object of another,
    // the service answers with an error and no samples.
    const auto list = viewer.request(cpm::HistoryClient::make(cpm::history::Kind::search, "", "", 0));
    uint64_t state_oid = 0;
    for (const auto& o : list.objects()) {
        if (o.name() == "vehicleState/1") state_oid = o.oid();
    }
    ASSERT_NE(state_oid, 0u) << "the object list names vehicleState/1";
    HistoryRequest by_oid = cpm::HistoryClient::make(cpm::history::Kind::latest, "", "", 0);
    by_oid.oid(state_oid);
    HistoryRequest disguised = cpm::HistoryClient::make(cpm::history::Kind::latest, "vehicleCommandDirect", "", 0);
    disguised.oid(state_oid);
    for (const auto& rq : {by_oid, disguised}) {
        const auto reply = commander.request(rq);
        EXPECT_TRUE(reply.samples().empty()) << reply.status();
        EXPECT_EQ(reply.status(), "error");
        EXPECT_NE(reply.error().find("names its topic"), std::string::npos) << reply.error();
    }
}

TEST(Security, ASecuredLabDrives)
{
    // A simulated car (simulator and bridge), its state machine and the history, each a process
    // with only its own grant; a viewer sees the car drive and asks the history about it.
    Lab lab;
    cpm::security::add_node(lab.dir, "car", {.publish = {"vehicleState", "vehicleObservation", "rangeSensors"},
                                             .subscribe = {"vehicleCommand*", "stopRequest", "vehicleObservation"}});
    cpm::security::add_node(lab.dir, "fsm", {.publish = {"vehicleCommandDirect", "fsmStatus", "stopRequest"},
                                             .subscribe = {"vehicleState", "rangeSensors", "arucoMarkers", "stopRequest"}});
    cpm::security::add_node(lab.dir, "history", {.publish = {"historyReply*", "historyStatus"}, .subscribe = {"*"}});
    cpm::security::add_node(lab.dir, "watcher", {.publish = {}, .subscribe = {"vehicleObservation", "vehicleState", "fsmStatus"}});
    const std::string root = cpm_test::source_dir();
    Process history({built_program("cpm_history"), "--security", lab.node("history")});
    Process car({built_program("cpm"), "vehicle", "sim", "--id", "5", "--map", root + "/scenarios/maps/corridor.json", "--start",
                 "0,-0.01,0", "--security", lab.node("car")});
    Process fsm({built_program("fsm_node"), "--vehicle_id", "5", "--fsm", root + "/scenarios/fsm/corridor.json", "--security", lab.node("fsm")});

    cpm::Participant watcher_p(secured(lab.node("watcher")));
    cpm::ReaderAbstract<VehicleObservation> observations(watcher_p, "vehicleObservation", {.keep_all = true});
    cpm::ReaderAbstract<FsmStatus> status(watcher_p, "fsmStatus", {.reliable = true, .keep_all = true, .transient_local = true});
    double x_min = 1e9, x_max = -1e9;
    bool fsm_seen = false;
    const bool drove = cpm_test::wait_until([&] {
        for (const auto& o : observations.take()) x_min = std::min(x_min, o.pose().x()), x_max = std::max(x_max, o.pose().x());
        fsm_seen = fsm_seen || !status.take().empty();
        return fsm_seen && x_max - x_min > 1.0;
    }, 60s, 20ms);
    EXPECT_TRUE(drove) << "moved " << x_max - x_min << " m, fsm status seen: " << fsm_seen << "\ncar: " << car.errors()
                       << "\nfsm: " << fsm.errors();
    cpm::HistoryClient ask(watcher_p, 10s);
    const auto reply = ask.latest("vehicleState", "5");
    EXPECT_EQ(reply.status(), "ok") << reply.error();
    car.kill(SIGINT);
    EXPECT_EQ(car.wait(10s), 0) << car.errors();
}
