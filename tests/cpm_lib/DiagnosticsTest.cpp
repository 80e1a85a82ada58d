// The one checker every file loader uses: how findings are named, "did you mean", and the
// error that carries them all.
#include <cpm/Diagnostics.hpp>
#include <cpm/checkers/JsonChecker.hpp>
#include <cpm/checkers/YamlChecker.hpp>

#include <gtest/gtest.h>

using cpm::Checker;
using cpm::did_you_mean;

TEST(Diagnostics, ATypoIsMatchedToTheKeyItIsCloseTo)
{
    const std::vector<std::string> known{"duration", "domain", "world", "vehicles"};
    EXPECT_EQ(did_you_mean("duraton", known), "duration");   // a letter missing
    EXPECT_EQ(did_you_mean("wrold", known), "world");        // two letters swapped
    EXPECT_EQ(did_you_mean("vehicels", known), "vehicles");
    EXPECT_EQ(did_you_mean("colour", known), std::nullopt);  // nothing like it
    EXPECT_EQ(did_you_mean("world", known), std::nullopt);   // known: no typo
    // Short words allow one edit only: "dom" is not "domain".
    EXPECT_EQ(did_you_mean("dom", known), std::nullopt);
    // The closest wins over an earlier one that is also close.
    EXPECT_EQ(did_you_mean("mount_z", {"mount_x", "mount_z"}), std::nullopt);
    EXPECT_EQ(did_you_mean("mount_zz", {"mount_x", "mount_z"}), "mount_z");
}

TEST(Diagnostics, FindingsNameFileLineAndPathAndAllAreThrownTogether)
{
    Checker c("lab.yaml");
    c.error("vehicles[0].start", "outside the walls", 7);
    c.error("", "empty");
    c.unknown_key("$.colour", "colour", {"lane_width", "nodes"});
    c.warning("$.states", "no way out", 0);
    ASSERT_EQ(c.errors().size(), 3u);
    EXPECT_EQ(c.errors()[0].text(), "lab.yaml:7: vehicles[0].start: outside the walls");
    EXPECT_EQ(c.errors()[1].text(), "lab.yaml: empty");
    EXPECT_EQ(c.errors()[2].text(), "lab.yaml: $.colour: unknown key; known: lane_width, nodes");
    ASSERT_EQ(c.warnings().size(), 1u);
    EXPECT_EQ(c.warnings()[0].severity, cpm::Diagnostic::Severity::warning);
    try {
        c.throw_if_errors();
        FAIL() << "no error thrown";
    } catch (const cpm::Error& e) {  // one catch covers every file error
        EXPECT_EQ(std::string(e.what()), "lab.yaml:7: vehicles[0].start: outside the walls\nlab.yaml: empty\n"
                                         "lab.yaml: $.colour: unknown key; known: lane_width, nodes");
        const auto* file_error = dynamic_cast<const cpm::FileError*>(&e);
        ASSERT_NE(file_error, nullptr);
        EXPECT_EQ(file_error->diagnostics().size(), 3u);
    }
    Checker clean("ok.json");
    clean.warning("$", "only a warning");
    EXPECT_NO_THROW(clean.throw_if_errors());
}

TEST(Diagnostics, ALoadResultHoldsAValueOnlyWithoutErrors)
{
    Checker bad("a.json");
    bad.error("$.x", "wrong");
    auto failed = bad.result<int>(42);
    EXPECT_FALSE(failed.ok());
    EXPECT_FALSE(failed.value.has_value());
    EXPECT_THROW(failed.take_or_throw(), cpm::FileError);

    Checker good("b.json");
    auto loaded = good.result<int>(42);
    ASSERT_TRUE(loaded.ok());
    EXPECT_EQ(loaded.take_or_throw(), 42);
}

TEST(Diagnostics, TheJsonCheckerNamesPathAndValueAndGoesOn)
{
    cpm::checkers::JsonChecker c("map.json");
    const auto doc = c.parse(R"({"x": "a", "n": 1e400, "id": 4294967299, "k": 3, "wlls": []})");
    ASSERT_FALSE(doc.has_value());  // 1e400 is not a JSON double nlohmann reads
    EXPECT_NE(c.errors().at(0).text().find("map.json: not valid JSON"), std::string::npos);

    cpm::checkers::JsonChecker d("map.json");
    const auto j = d.parse(R"({"x": "a", "id": 4294967299, "k": 3, "wlls": []})");
    ASSERT_TRUE(j.has_value());
    EXPECT_EQ(d.number((*j)["x"], "$.x"), std::nullopt);
    EXPECT_EQ(d.integer((*j)["id"], "$.id"), std::nullopt);  // would wrap to 3 as an int
    EXPECT_EQ(d.number((*j)["k"], "$.k", 0, 2), std::nullopt);
    EXPECT_EQ(d.number_member(*j, "$", "y"), std::nullopt);
    d.keys(*j, "$", {"x", "id", "k", "walls"});
    std::vector<std::string> texts;
    for (const auto& e : d.errors()) texts.push_back(e.text());
    EXPECT_EQ(texts, (std::vector<std::string>{
                         "map.json: $.x: expected a finite number, got \"a\"",
                         "map.json: $.id: expected an integer in -2147483648..2147483647, got 4294967299",
                         "map.json: $.k: 3 is out of range [0, 2]",
                         "map.json: $: missing \"y\"",
                         "map.json: $.wlls: unknown key (did you mean 'walls'?); known: x, id, k, walls",
                     }));
}

TEST(Diagnostics, TheYamlCheckerNamesTheLine)
{
    cpm::checkers::YamlChecker c("lab.yaml");
    const YAML::Node root = YAML::Load("name: a\nduration: soon\nport: 70000\nflag: perhaps\nspeed: .nan\n");
    EXPECT_EQ(c.duration(root["duration"], "duration"), std::nullopt);
    EXPECT_EQ(c.integer(root["port"], "port", 1, 65535), std::nullopt);
    EXPECT_EQ(c.boolean(root["flag"], "flag"), std::nullopt);
    EXPECT_EQ(c.number(root["speed"], "speed"), std::nullopt);  // NaN is bad input
    ASSERT_EQ(c.errors().size(), 4u);
    EXPECT_EQ(c.errors()[0].text(), "lab.yaml:2: duration: 'soon' is not a duration (a number with ns, us, ms, s, m or h: 30s, 400ms)");
    EXPECT_EQ(c.errors()[1].text(), "lab.yaml:3: port: 70000 is out of range (1 to 65535)");
    EXPECT_EQ(c.errors()[2].text(), "lab.yaml:4: flag: expected true or false");
    EXPECT_EQ(c.errors()[3].text(), "lab.yaml:5: speed: '.nan' is not a finite number");
}
