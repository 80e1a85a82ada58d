#include <cpm/fsm/Loader.hpp>
#include <cpm/fsm/Uxf.hpp>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <fstream>
#include <sstream>
#include <cpm_test/SourceDir.hpp>

using namespace cpm::fsm;
using nlohmann::json;

namespace {

std::string text_of(const std::string& path)
{
    std::ifstream in(path);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
}

std::string uxf(const std::string& elements) { return "<diagram program=\"umlet\">" + elements + "</diagram>"; }

std::string state_box(int x, const std::string& params)
{
    return "<element><id>UMLState</id><coordinates><x>" + std::to_string(x) +
           "</x><y>0</y><w>100</w><h>100</h></coordinates><panel_attributes>title\n--\n" + params +
           "\n--\n</panel_attributes></element>";
}

std::string arrow(int x, const std::string& params)
{
    return "<element><id>Relation</id><coordinates><x>" + std::to_string(x) +
           "</x><y>40</y><w>120</w><h>20</h></coordinates><panel_attributes>lt=-&gt;\n" + params +
           "</panel_attributes><additional_attributes>10;10;110;10</additional_attributes></element>";
}

}  // namespace

TEST(FsmUxf, TheShippedDrawingIsTheSameMachineAsTheShippedJson)
{
    const std::string dir = cpm_test::source_dir() + "/scenarios/fsm/";
    auto sut = convert_uxf(text_of(dir + "corridor.uxf"), "corridor.uxf");
    ASSERT_TRUE(sut.errors.empty()) << sut.errors[0].text();
    EXPECT_EQ(json::parse(sut.json), json::parse(text_of(dir + "corridor.json")));
    EXPECT_TRUE(load_file(dir + "corridor.uxf").ok());
}

TEST(FsmUxf, ArrowsWithoutFromAndToJoinTheBoxesTheyTouch)
{
    auto sut = convert_uxf(uxf(state_box(0, "\"id\": 4\n\"type\": \"Motor\"\n\"root\": true") +
                               state_box(200, "id: 9\ntype: Stop") + arrow(90, "\"id\": 1, \"type\": \"Always\"")),
                           "d.uxf");
    ASSERT_TRUE(sut.errors.empty()) << sut.errors[0].text();
    auto j = json::parse(sut.json);
    EXPECT_EQ(j["root"], 4);
    EXPECT_EQ(j["transitions"][0]["from"], 4);
    EXPECT_EQ(j["transitions"][0]["to"], 9);
    EXPECT_EQ(j["states"][1]["type"], "Stop");  // bare words are strings
}

TEST(FsmUxf, ErrorsNameTheDrawingsElement)
{
    const std::string file = "/tmp/cpm_fsm_uxf_" + std::to_string(::getpid()) + ".uxf";
    std::ofstream(file) << uxf(state_box(0, "\"id\": 0\n\"type\": \"FollowWal\"") + state_box(200, "\"id\": 1\n\"type\": \"Stop\"") +
                               arrow(90, "\"id\": 0, \"type\": \"Finished\""));
    auto sut = load_file(file);
    ASSERT_FALSE(sut.ok());
    bool named = false;
    for (auto& e : sut.errors) named = named || e.where == file + ": $.states[0].type = element 0 (UMLState at 0,0)";
    EXPECT_TRUE(named) << sut.errors[0].text();

    auto dangling = convert_uxf(uxf(state_box(0, "\"id\": 0\n\"type\": \"Motor\"") + arrow(500, "\"id\": 0, \"type\": \"Always\"")), "e.uxf");
    ASSERT_EQ(dangling.errors.size(), 2u);
    EXPECT_EQ(dangling.errors[0].text(), "e.uxf: element 1 (Relation at 500,40): the arrow's start touches no state box and the transition gives no \"from\"");
    auto not_uxf = convert_uxf("this is not XML", "f.uxf");
    ASSERT_EQ(not_uxf.errors.size(), 1u);
    EXPECT_NE(not_uxf.errors[0].text().find("f.uxf: not a readable UMLet file"), std::string::npos);
    std::remove(file.c_str());
}
