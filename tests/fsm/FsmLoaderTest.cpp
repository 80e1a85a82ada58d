#include <cpm/fsm/Loader.hpp>

#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <unistd.h>

using namespace cpm::fsm;

namespace {

std::string all(const std::vector<Diagnostic>& list)
{
    std::string s;
    for (auto& d : list) s += d.text() + "\n";
    return s;
}

bool has(const std::vector<Diagnostic>& list, const std::string& where, const std::string& message_part)
{
    for (auto& d : list) {
        if (d.where == where && d.message.find(message_part) != std::string::npos) return true;
    }
    return false;
}

}  // namespace

TEST(FsmLoader, AGoodMachineLoadsWithDefaultsAndNoDiagnostics)
{
    auto sut = load_json(R"({"root": 0,
        "states": [{"id": 0, "type": "FollowWall", "side": "left", "clearance": 0.3},
                   {"id": 1, "type": "Stop"}],
        "transitions": [{"id": 0, "type": "SensorLevel", "from": 0, "to": 1, "sensor": "front", "level": 0.5, "direction": "below"}]})",
                         "car.json");
    EXPECT_TRUE(sut.ok()) << all(sut.errors);
    EXPECT_TRUE(sut.warnings.empty()) << all(sut.warnings);
    ASSERT_TRUE(sut.machine);
    EXPECT_EQ(sut.machine->states().size(), 2u);
    EXPECT_EQ(sut.machine->active().type(), "FollowWall");
}

TEST(FsmLoader, ReportsEveryErrorAtOnceWithItsJsonPath)
{
    auto sut = load_json(R"({"root": 7,
        "states": [{"id": 0, "type": "FolowWall"},
                   {"id": 1, "type": "Motor", "speed": "fast", "colour": 3},
                   {"id": 1, "type": "Stop"},
                   {"id": 2, "type": "FollowWallRamp", "target_clearance": 0.5},
                   {"id": 3, "type": "BasicFollowWall", "side": "up"},
                   {"id": 4, "type": "Idle"}],
        "transitions": [{"id": 0, "type": "Distance", "from": 1, "to": 9, "distance": 1},
                        {"id": 0, "type": "Always", "from": 8, "to": 1},
                        {"id": 1, "type": "Finished", "from": 4, "to": 1},
                        {"id": 2, "type": "ArucoGateFound", "from": 1, "to": 4},
                        {"id": 3, "type": "Teleport", "from": 1, "to": 4},
                        {"id": 4, "type": "Timeout", "from": 1, "to": 4},
                        {"id": 5, "type": "SensorLevel", "from": 1, "to": 4, "sensor": "back", "level": 0.5},
                        {"id": 6, "type": "Timeout", "from": 1, "to": 4, "seconds": -1}]})",
                         "car.json");
    EXPECT_FALSE(sut.ok());
    EXPECT_FALSE(sut.machine);
    const auto& e = sut.errors;
    EXPECT_TRUE(has(e, "car.json: $.states[0].type", "unknown state type \"FolowWall\" (did you mean \"FollowWall\"?)")) << all(e);
    EXPECT_TRUE(has(e, "car.json: $.states[1].speed", "expected a number, got \"fast\"")) << all(e);
    EXPECT_TRUE(has(e, "car.json: $.states[1].colour", "unknown parameter of Motor")) << all(e);
    EXPECT_TRUE(has(e, "car.json: $.states[2].id", "duplicate state id 1")) << all(e);
    EXPECT_TRUE(has(e, "car.json: $.states[3]", "FollowWallRamp needs parameter \"distance\"")) << all(e);
    EXPECT_TRUE(has(e, "car.json: $.states[4].side", "expected \"left\" or \"right\", got \"up\"")) << all(e);
    EXPECT_TRUE(has(e, "car.json: $.root", "state 7 does not exist")) << all(e);
    EXPECT_TRUE(has(e, "car.json: $.transitions[0].to", "state 9 does not exist")) << all(e);
    EXPECT_TRUE(has(e, "car.json: $.transitions[1].id", "duplicate transition id 0")) << all(e);
    EXPECT_TRUE(has(e, "car.json: $.transitions[1].from", "state 8 does not exist")) << all(e);
    EXPECT_TRUE(has(e, "car.json: $.transitions[2]", "Finished from state 4 (Idle), which never finishes")) << all(e);
    EXPECT_TRUE(has(e, "car.json: $.transitions[3]", "ArucoGateFound into state 4 (Idle), which cannot take a target")) << all(e);
    EXPECT_TRUE(has(e, "car.json: $.transitions[4].type", "unknown transition type \"Teleport\"")) << all(e);
    EXPECT_TRUE(has(e, "car.json: $.transitions[5]", "Timeout needs parameter \"seconds\"")) << all(e);
    // A parameter given but wrong is said once, not also as missing.
    EXPECT_TRUE(has(e, "car.json: $.transitions[6].sensor", "got \"back\"")) << all(e);
    EXPECT_FALSE(has(e, "car.json: $.transitions[6]", "needs parameter \"sensor\"")) << all(e);
    EXPECT_TRUE(has(e, "car.json: $.transitions[7].seconds", "got -1")) << all(e);
    EXPECT_FALSE(has(e, "car.json: $.transitions[7]", "needs parameter \"seconds\"")) << all(e);
    EXPECT_EQ(e.size(), 16u) << all(e);
}

TEST(FsmLoader, MissingRootAndBadJsonAreNamed)
{
    auto no_root = load_json(R"({"states": [{"id": 0, "type": "Stop"}], "transitions": []})", "a.json");
    EXPECT_TRUE(has(no_root.errors, "a.json: $", "missing \"root\"")) << all(no_root.errors);
    auto broken = load_json("{\"root\": 0,", "b.json");
    ASSERT_EQ(broken.errors.size(), 1u);
    EXPECT_NE(broken.errors[0].text().find("b.json: not valid JSON"), std::string::npos);
    auto missing = load_file("/nonexistent/machine.json");
    ASSERT_EQ(missing.errors.size(), 1u);
    EXPECT_EQ(missing.errors[0].text(), "/nonexistent/machine.json: cannot open the state machine file: no such file");
}

TEST(FsmLoader, WarnsAboutUnreachableStatesAndStatesWithNoWayOut)
{
    auto sut = load_json(R"({"root": 0,
        "states": [{"id": 0, "type": "Motor", "distance": 1}, {"id": 1, "type": "FollowWall"},
                   {"id": 2, "type": "Stop"}, {"id": 3, "type": "Motor", "final": true}],
        "transitions": [{"id": 0, "type": "Finished", "from": 0, "to": 1}]})",
                         "w.json");
    EXPECT_TRUE(sut.ok()) << all(sut.errors);
    EXPECT_TRUE(has(sut.warnings, "w.json: $.states", "state 2 (Stop) cannot be reached")) << all(sut.warnings);
    EXPECT_TRUE(has(sut.warnings, "w.json: $.states", "state 1 (FollowWall) has no way out")) << all(sut.warnings);
    EXPECT_FALSE(has(sut.warnings, "w.json: $.states", "state 3 (Motor) has no way out")) << all(sut.warnings);
    EXPECT_FALSE(has(sut.warnings, "w.json: $.states", "state 2 (Stop) has no way out")) << all(sut.warnings);
}

TEST(FsmLoader, NestedMachineFilesMustExistAndMustNotIncludeThemselves)
{
    const std::string dir = "/tmp/cpm_fsm_test_" + std::to_string(::getpid());
    ::mkdir(dir.c_str(), 0777);
    std::ofstream(dir + "/a.json") << R"({"root": 0, "states": [{"id": 0, "type": "FSMState", "file": "b.json"}], "transitions": []})";
    std::ofstream(dir + "/b.json") << R"({"root": 0, "states": [{"id": 0, "type": "FSMState", "file": "a.json", "final": true}], "transitions": []})";
    std::ofstream(dir + "/c.json") << R"({"root": 0, "states": [{"id": 0, "type": "FSMState", "file": "nowhere.json"}], "transitions": []})";
    auto cyclic = load_file(dir + "/a.json");
    EXPECT_TRUE(has(cyclic.errors, dir + "/b.json: $.states[0].file", "includes itself (cycle)")) << all(cyclic.errors);
    auto missing = load_file(dir + "/c.json");
    EXPECT_TRUE(has(missing.errors, dir + "/c.json: $.states[0].file", "nowhere.json does not exist")) << all(missing.errors);
    auto no_final = load_json(R"({"root": 0, "states": [{"id": 0, "type": "FSMState",
        "machine": {"root": 0, "states": [{"id": 0, "type": "Stop"}], "transitions": []}}], "transitions": []})", "n.json");
    EXPECT_TRUE(has(no_final.errors, "n.json: $.states[0]", "no state marked \"final\"")) << all(no_final.errors);
    for (const char* f : {"/a.json", "/b.json", "/c.json"}) std::remove((dir + f).c_str());
    ::rmdir(dir.c_str());
}

TEST(FsmLoader, KnownTypesDocumentEveryParameterWithItsDefault)
{
    size_t states = 0, transitions = 0;
    for (const auto& t : known_types()) {
        (t.is_state ? states : transitions)++;
        for (const auto& p : t.parameters) EXPECT_FALSE(p.meaning.empty()) << t.type << "." << p.name;
    }
    EXPECT_EQ(states, 9u);
    EXPECT_EQ(transitions, 6u);
}

TEST(FsmLoader, ParametersOutOfTheirRangeAndIdsBeyond32BitsAreErrorsWithTheirJsonPath)
{
    auto sut = load_json(R"({"root": 0,
        "states": [{"id": 0, "type": "FollowWall", "clearance": -5, "speed": 1e300},
                   {"id": 1, "type": "Motor", "steering": 50},
                   {"id": 4294967299, "type": "Stop"},
                   {"id": 2, "type": "Stop"}],
        "transitions": [{"id": 0, "type": "Timeout", "from": 0, "to": 1, "seconds": -1},
                        {"id": 1, "type": "Always", "from": 1, "to": 2}]})",
                         "car.json");
    EXPECT_FALSE(sut.ok());
    EXPECT_TRUE(has(sut.errors, "car.json: $.states[0].clearance", "expected a number in 0.02..3")) << all(sut.errors);
    EXPECT_TRUE(has(sut.errors, "car.json: $.states[0].clearance", "got -5")) << all(sut.errors);
    EXPECT_TRUE(has(sut.errors, "car.json: $.states[0].speed", "got 1e+300")) << all(sut.errors);
    EXPECT_TRUE(has(sut.errors, "car.json: $.states[1].steering", "expected a number in -1..1")) << all(sut.errors);
    EXPECT_TRUE(has(sut.errors, "car.json: $.states[2].id", "expected an integer in -2147483648..2147483647, got 4294967299"))
        << all(sut.errors);
    EXPECT_TRUE(has(sut.errors, "car.json: $.transitions[0].seconds", "expected a number in 0..86400")) << all(sut.errors);
}

TEST(FsmLoader, EveryNumericParameterHasARange)
{
    for (const auto& info : known_types()) {
        for (const auto& p : info.parameters) {
            if (p.kind != "number" && p.kind != "integer") continue;
            EXPECT_GT(p.min, -1e299) << info.type << "." << p.name;
            EXPECT_LT(p.max, 1e299) << info.type << "." << p.name;
        }
    }
}

TEST(FsmLoader, AMachineWithoutStatesAndADirectoryAreErrorsNamingTheFile)
{
    auto empty = load_json(R"({"root": 0, "states": []})", "empty.json");
    EXPECT_TRUE(has(empty.errors, "empty.json: $.states", "the machine has no states")) << all(empty.errors);
    auto dir = load_file("/tmp");
    ASSERT_EQ(dir.errors.size(), 1u);
    EXPECT_EQ(dir.errors[0].text(), "/tmp: cannot read it as the state machine file: it is a directory");
}
