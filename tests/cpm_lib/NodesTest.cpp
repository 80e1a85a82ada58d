// The table of which program uses which topic (cpm/nodes.hpp) against the table of topics.
#include <cpm/Error.hpp>
#include <cpm/nodes.hpp>
#include <cpm/topics.hpp>

#include <gtest/gtest.h>

#include <algorithm>

namespace nodes = cpm::nodes;

TEST(Nodes, EveryTopicARowNamesIsInTheTopicTable)
{
    for (const auto& row : nodes::all()) {
        for (const auto* list : {&row.publish, &row.subscribe}) {
            for (const auto& t : *list) {
                if (t.find_first_of("*?") == std::string::npos) {
                    EXPECT_NE(cpm::topics::find(t), nullptr) << row.name << ": " << t << " is no topic of topics.hpp";
                    continue;
                }
                // A pattern matches a topic of the table (or is "anything").
                const bool any = std::any_of(cpm::topics::all.begin(), cpm::topics::all.end(),
                                             [&](const cpm::TopicSpec* s) { return nodes::matches(s->name, {t}); });
                EXPECT_TRUE(any) << row.name << ": the pattern " << t << " matches no topic";
            }
        }
    }
}

TEST(Nodes, EveryProgramThatWritesADataTopicIsListedAndNamesAreUnique)
{
    std::vector<std::string> names;
    for (const auto& row : nodes::all()) names.push_back(row.name);
    std::sort(names.begin(), names.end());
    EXPECT_EQ(std::adjacent_find(names.begin(), names.end()), names.end()) << "a row name twice";
    // Every topic of the table has a writer among the rows (else nobody in cpm makes it), but the
    // log level: cpm's programs follow it, cpm_lab's Lab Control Center sets it.
    for (const auto* topic : cpm::topics::all) {
        if (topic == &cpm::topics::log_level) continue;
        const bool written = std::any_of(nodes::all().begin(), nodes::all().end(),
                                         [&](const nodes::NodeSpec& r) { return nodes::matches(topic->name, r.publish); });
        EXPECT_TRUE(written) << topic->name << " has no writer in cpm/nodes.hpp";
    }
}

TEST(Nodes, ThePartsEveryProgramHasAreGrantedToEveryNode)
{
    EXPECT_EQ(nodes::builtin_publish(), (std::vector<std::string>{"log", "readyStatus", "parameterRequest"}));
    EXPECT_EQ(nodes::builtin_subscribe(), (std::vector<std::string>{"logLevel", "systemTrigger", "parameter"}));
    const auto kinds = nodes::kinds();
    EXPECT_EQ(std::count(kinds.begin(), kinds.end(), "logging"), 0) << "a part is no program";
    EXPECT_EQ(std::count(kinds.begin(), kinds.end(), "fsm_node"), 1);
}

TEST(Nodes, APlayerLeavesOutWhatSteersTheLabAndPlaysWhatHappened)
{
    const auto control = nodes::control_topics();
    for (const char* t : {"systemTrigger", "readyStatus", "parameter", "parameterRequest", "historyRequest", "historyReply",
                          "historyReply/vehicleState", "historyStatus"}) {
        EXPECT_TRUE(nodes::matches(t, control)) << t << " would be replayed into a live lab";
    }
    for (const char* t : {"vehicleState", "vehicleObservation", "fsmStatus", "log", "stopRequest", "arucoMarkers", "cameraFrame"}) {
        EXPECT_FALSE(nodes::matches(t, control)) << t << " is what happened: a player plays it";
    }
}

TEST(Nodes, ARowHasItsTimerAndAnUnknownNameListsTheKnown)
{
    EXPECT_EQ(nodes::find("fsm_node").timer(3), "fsm_node_3");
    EXPECT_EQ(nodes::find("central_routing").timer(0), "central_routing");
    EXPECT_EQ(nodes::find("cpm_history").timer, nullptr);
    try {
        (void)nodes::find("fsm_nod");
        FAIL() << "no error";
    } catch (const cpm::Error& e) {
        EXPECT_NE(std::string(e.what()).find("no node kind 'fsm_nod' (known: firmware_sim, firmware_hil, vehicle_bridge"), std::string::npos) << e.what();
    }
}
