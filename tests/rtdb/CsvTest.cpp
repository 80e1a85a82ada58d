// Samples as CSV and back: the encoder writes what Fast DDS writes for every field, cells quote
// and unquote as RFC 4180 says, an import names each row that does not parse by line and column
// and leaves no file behind.
#include <cpm/Error.hpp>
#include <cpm/rtdb/Csv.hpp>
#include <cpm/rtdb/IdlDecoder.hpp>
#include <cpm/rtdb/Recording.hpp>
#include <cpm/rtdb/Requests.hpp>

#include <ArucoMarkersPubSubTypes.h>
#include <FsmStatusPubSubTypes.h>
#include <VehicleCommandTrajectoryPubSubTypes.h>
#include <VehicleStatePubSubTypes.h>

#include <cpm_test/TempDir.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <limits>
#include <sstream>

#include "serialized.hpp"

using namespace cpm::rtdb;
namespace fs = std::filesystem;

using cpm_test::TempDir;

namespace {

const IdlDecoder& types()
{
    const IdlDecoder* t = IdlDecoder::lab_types();
    if (!t) throw std::runtime_error("no IDL");
    return *t;
}

VehicleState a_state(double x)
{
    VehicleState s;
    s.vehicle_id(7);
    s.header().create_stamp().nanoseconds(1'700'000'000'123'456'789ull);
    s.header().valid_after_stamp().nanoseconds(1'700'000'000'183'456'789ull);
    s.pose().x(x);
    s.pose().y(-0.1 / 3);
    s.pose().yaw(std::numeric_limits<double>::quiet_NaN());
    s.speed(std::numeric_limits<double>::infinity());
    s.odometer_distance(1e-300);
    s.battery_voltage(7.4);
    s.is_real(true);
    return s;
}


}  // namespace

TEST(Csv, EncodeWritesTheBytesFastDdsWrites)
{
    const auto state = serialized<VehicleStatePubSubType>(a_state(1.5));
    EXPECT_EQ(types().encode("VehicleState", *types().decode("VehicleState", state)), state);

    VehicleCommandTrajectory traj;
    traj.vehicle_id(3);
    for (int i = 0; i < 3; ++i) {
        TrajectoryPoint p;
        p.t().nanoseconds(100u * i);
        p.px(i * 0.5);
        p.vy(-i);
        traj.trajectory_points().push_back(p);
    }
    const auto t = serialized<VehicleCommandTrajectoryPubSubType>(traj);
    EXPECT_EQ(types().encode("VehicleCommandTrajectory", *types().decode("VehicleCommandTrajectory", t)), t);

    FsmStatus fsm;
    fsm.vehicle_id(2);
    fsm.state_id(4);
    fsm.state_type("FollowWall, \"right\"");
    fsm.entered_ns(123456789);
    fsm.last_transition_id(-1);
    const auto f = serialized<FsmStatusPubSubType>(fsm);
    EXPECT_EQ(types().encode("FsmStatus", *types().decode("FsmStatus", f)), f);

    ArucoMarkers markers;
    ArucoMarker m;
    m.id(7);
    m.distance(1.25);
    m.corners()[2].x(640.5);
    m.pose().yaw(-0.25);
    markers.markers().push_back(m);
    markers.markers().push_back(m);
    const auto a = serialized<ArucoMarkersPubSubType>(markers);
    EXPECT_EQ(types().encode("ArucoMarkers", *types().decode("ArucoMarkers", a)), a);
}

TEST(Csv, EncodeNamesTheFieldAndValueThatDoNotFit)
{
    auto message = [](const nlohmann::json& j) {
        try {
            (void)types().encode("VehicleState", j);
            return std::string("accepted");
        } catch (const cpm::Error& e) {
            return std::string(e.what());
        }
    };
    EXPECT_EQ(message({{"vehicle_id", 300}}), "vehicle_id: 300 is out of range");
    EXPECT_EQ(message({{"vehicle_id", "seven"}}), "vehicle_id: 'seven' is not a whole number");
    EXPECT_EQ(message({{"pose", {{"x", "far"}}}}), "pose.x: 'far' is not a number");
    EXPECT_EQ(message({{"header", {{"create_stamp", {{"nanoseconds", "-5"}}}}}}), "header.create_stamp.nanoseconds: '-5' is negative");
    EXPECT_EQ(message({{"vehicle_id", "7"}, {"pose", {{"x", "nan"}}}}), "accepted");
}

TEST(Csv, CellsQuoteAndReadBack)
{
    const std::vector<std::string> cells = {"plain", "with, comma", "with \"quotes\"", "two\nlines", "", "[1,2]"};
    const std::string text = csv::line(cells) + csv::line({"a", "b", "c", "d", "e", "f"});
    std::istringstream in(text);
    std::vector<std::string> back;
    size_t line = 0;
    ASSERT_TRUE(csv::read_record(in, back, line));
    EXPECT_EQ(back, cells);
    EXPECT_EQ(line, 2u) << "the record spans two lines";
    ASSERT_TRUE(csv::read_record(in, back, line));
    EXPECT_EQ(back.size(), 6u);
    EXPECT_EQ(line, 3u);
    EXPECT_FALSE(csv::read_record(in, back, line));

    std::istringstream open("a,\"never closed\n");
    line = 0;
    try {
        csv::read_record(open, back, line);
        FAIL() << "an open quote was read";
    } catch (const cpm::Error& e) {
        EXPECT_STREQ(e.what(), "line 1, column 2: a quoted cell is never closed");
    }
}

TEST(Csv, FlattenNamesFieldsByIdlPathAndKeepsEveryValue)
{
    const auto j = *types().decode("VehicleState", serialized<VehicleStatePubSubType>(a_state(1.5)));
    const auto cells = csv::flatten(j, types().field_paths("VehicleState"));
    ASSERT_FALSE(cells.empty());
    EXPECT_EQ(cells[0].first, "header.create_stamp.nanoseconds") << "in the IDL's order";
    EXPECT_EQ(cells[2].first, "vehicle_id");
    std::map<std::string, std::string> by_path(cells.begin(), cells.end());
    EXPECT_EQ(by_path.at("header.create_stamp.nanoseconds"), "1700000000123456789");
    EXPECT_EQ(by_path.at("pose.x"), "1.5");
    EXPECT_EQ(by_path.at("pose.yaw"), "nan");
    EXPECT_EQ(by_path.at("speed"), "inf");
    EXPECT_EQ(by_path.at("is_real"), "true");
    EXPECT_EQ(std::stod(by_path.at("pose.y")), -0.1 / 3) << "doubles read back exactly";
    EXPECT_EQ(std::stod(by_path.at("odometer_distance")), 1e-300);
}

TEST(Csv, ImportNamesEveryRowThatDoesNotParseAndWritesNothing)
{
    TempDir dir;
    const std::string out = dir.file("imported.db");
    std::istringstream in("data_ns,vehicle_id,pose.x,speed\n"
                          "1000,7,0.5,1\n"
                          "2000,7,zero,1\n"
                          "3000,700,0.5,1\n"
                          "4000,7,0.5\n"
                          "soon,7,0.5,1\n");
    try {
        (void)csv::import(in, "drive.csv", "vehicleState", "VehicleState", types(), out);
        FAIL() << "bad rows were imported";
    } catch (const cpm::Error& e) {
        EXPECT_EQ(std::string(e.what()),
                  "drive.csv:3: column pose.x (3): 'zero' is not a number\n"
                  "drive.csv:4: column vehicle_id (2): '700' is out of range\n"
                  "drive.csv:5: 3 cells, the header names 4\n"
                  "drive.csv:6: column data_ns (1): 'soon' is not a time in nanoseconds");
    }
    EXPECT_FALSE(fs::exists(out));
    std::istringstream unknown("data_ns,wheels\n1,4\n");
    try {
        (void)csv::import(unknown, "w.csv", "vehicleState", "VehicleState", types(), out);
        FAIL();
    } catch (const cpm::Error& e) {
        EXPECT_EQ(std::string(e.what()), "w.csv:1: column 2 'wheels' is no field of VehicleState");
    }
    EXPECT_FALSE(fs::exists(out));
    std::istringstream empty("");
    try {
        (void)csv::import(empty, "empty.csv", "vehicleState", "VehicleState", types(), out);
        FAIL();
    } catch (const cpm::Error& e) {
        EXPECT_EQ(std::string(e.what()), "empty.csv: empty (the first line names the columns)") << "the file named once";
    }
}

TEST(Csv, ImportedRowsAnswerAsSamplesOfTheirKeys)
{
    TempDir dir;
    const std::string out = dir.file("imported.db");
    std::istringstream in("vehicle_id,header.create_stamp.nanoseconds,header.valid_after_stamp.nanoseconds,pose.x\n"
                          "7,1000,1060,0.5\n"
                          "8,1500,1560,9\n"
                          "7,2000,2060,1.5\n");
    const auto report = csv::import(in, "drive.csv", "vehicleState", "VehicleState", types(), out);
    EXPECT_EQ(report.rows, 3u);
    EXPECT_EQ(report.objects, 2u);
    const auto rec = load_recording(out);
    const auto oid = rec.store->find("vehicleState", "7");
    ASSERT_TRUE(oid);
    auto r = rec.store->range(*oid, 0, 10000, By::data);
    ASSERT_EQ(r.samples.size(), 2u);
    EXPECT_EQ(r.samples[1].commit_ns, 2000u) << "committed at its data time";
    EXPECT_EQ(r.samples[1].valid_after_ns, 2060u);
    EXPECT_EQ(types().decode("VehicleState", r.samples[1].payload)->at("pose").at("x"), 1.5);
}
