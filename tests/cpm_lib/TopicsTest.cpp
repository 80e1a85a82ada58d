// cpm/topics.hpp: the lab's topic table. Names are cpm_lab's on the wire, each is listed once
// and found by name, and the QoS a writer offers as the table says satisfies what the table's
// reader asks (DDS matches a reader only when the writer is at least as reliable and as durable).
#include <cpm/topics.hpp>

#include <gtest/gtest.h>

#include <map>
#include <set>
#include <string>

TEST(Topics, NamesAreTheLabsAndEachIsListedOnce)
{
    namespace t = cpm::topics;
    EXPECT_STREQ(t::vehicle_state.name, "vehicleState");
    EXPECT_STREQ(t::vehicle_command_direct.name, "vehicleCommandDirect");
    EXPECT_STREQ(t::vehicle_command_speed_curvature.name, "vehicleCommandSpeedCurvature");
    EXPECT_STREQ(t::vehicle_command_trajectory.name, "vehicleCommandTrajectory");
    EXPECT_STREQ(t::vehicle_observation.name, "vehicleObservation");
    EXPECT_STREQ(t::system_trigger.name, "systemTrigger");
    EXPECT_STREQ(t::ready_status.name, "readyStatus");
    EXPECT_STREQ(t::log.name, "log");
    EXPECT_STREQ(t::log_level.name, "logLevel");
    EXPECT_STREQ(t::parameter.name, "parameter");
    EXPECT_STREQ(t::parameter_request.name, "parameterRequest");
    std::set<std::string> names;
    std::map<std::string, std::set<std::string>> topics_of_type;
    for (const auto* spec : t::all) {
        EXPECT_TRUE(names.insert(spec->name).second) << spec->name << " listed twice";
        topics_of_type[spec->type_name].insert(spec->name);
        EXPECT_EQ(t::find(spec->name), spec);
        EXPECT_NE(std::string(spec->about), "");
    }
    EXPECT_EQ(t::find("vehiclestate"), nullptr);
    // One topic per type, but the two a positioning system adds: the simulator's truth beside
    // the camera's observation, and the overhead camera's frames beside the cars'.
    for (const auto& [type, topics] : topics_of_type) {
        if (type == "VehicleObservation") EXPECT_EQ(topics, (std::set<std::string>{"vehicleObservation", "vehicleObservationTruth"}));
        else if (type == "CameraFrame") EXPECT_EQ(topics, (std::set<std::string>{"cameraFrame", "ipsCameraFrame"}));
        else EXPECT_EQ(topics.size(), 1u) << type << " on " << topics.size() << " topics";
    }
    static_assert(t::find("historyReply") == &t::history_reply);
}

TEST(Topics, EveryWriterAsTheTableSaysMatchesEveryReaderAsTheTableSays)
{
    for (const auto* spec : cpm::topics::all) {
        if (spec->reader.reliable) {
            EXPECT_TRUE(spec->writer.reliable) << spec->name << ": a reliable reader needs a reliable writer";
        }
        if (spec->reader.transient_local) {
            EXPECT_TRUE(spec->writer.transient_local) << spec->name;
        }
        EXPECT_GE(spec->writer.history_depth, 1) << spec->name;
    }
    const auto mine = cpm::topics::vehicle_state.reader_for(7);
    EXPECT_EQ(mine.vehicle_id, 7);
    EXPECT_EQ(cpm::topics::vehicle_state.reader.vehicle_id, std::nullopt);  // the table's entry is unchanged
}
