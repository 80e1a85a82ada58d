// Parameters: a ParameterServer in this process, clients through cpm::parameter_*.
#include <cpm/Error.hpp>
#include <cpm/ParameterServer.hpp>
#include <cpm/get_parameter.hpp>
#include <cpm_test/Dds.hpp>
#include <cpm_test/Isolation.hpp>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <fstream>

#include <unistd.h>

using namespace std::chrono_literals;
using ::testing::HasSubstr;

namespace {

class ParameterTest : public ::testing::Test
{
protected:
    void SetUp() override { cpm_test::test_domain_id(); }  // clients use the default participant
    cpm::Participant server_side{cpm_test::isolated_options()};

    std::string write_file(const std::string& text, const std::string& extension = ".json")
    {
        const std::string path =
            "/tmp/cpm_params_" + std::to_string(getpid()) + "_" + std::to_string(files_++) + extension;
        std::ofstream(path) << text;
        paths_.push_back(path);
        return path;
    }
    void TearDown() override
    {
        for (auto& p : paths_) std::remove(p.c_str());
    }

    template <class F>
    std::string error_of(F&& f)
    {
        try {
            f();
        } catch (const cpm::Error& e) {
            return e.what();
        }
        return "(no error)";
    }

private:
    int files_ = 0;
    std::vector<std::string> paths_;
};

}  // namespace

TEST_F(ParameterTest, EveryTypeRoundTrips)
{
    cpm::ParameterServer sut(server_side);
    sut.set_bool("b", true);
    sut.set_int("i", -42);
    sut.set_uint64("u", 18'000'000'000'000'000'000ull);
    sut.set_double("d", 0.125);
    sut.set_string("s", "corridor");
    sut.set_ints("is", {1, -2, 3});
    sut.set_doubles("ds", {0.5, 1.5});

    EXPECT_EQ(cpm::parameter_bool("b"), true);
    EXPECT_EQ(cpm::parameter_int("i"), -42);
    EXPECT_EQ(cpm::parameter_uint64_t("u"), 18'000'000'000'000'000'000ull);
    EXPECT_EQ(cpm::parameter_double("d"), 0.125);
    EXPECT_EQ(cpm::parameter_string("s"), "corridor");
    EXPECT_EQ(cpm::parameter_ints("is"), (std::vector<int32_t>{1, -2, 3}));
    EXPECT_EQ(cpm::parameter_doubles("ds"), (std::vector<double>{0.5, 1.5}));
}

TEST_F(ParameterTest, WithoutAServerTheCallTimesOutWithAnErrorNamingTheParameter)
{
    const auto t0 = std::chrono::steady_clock::now();
    const std::string message = error_of([] { cpm::parameter_double("max_speed", 300ms); });
    const auto took = std::chrono::steady_clock::now() - t0;

    EXPECT_THAT(message, HasSubstr("'max_speed'"));
    EXPECT_THAT(message, HasSubstr("300 ms"));
    EXPECT_LT(took, 3000ms) << "the timeout was not honoured";
}

TEST_F(ParameterTest, UnknownNameIsAnErrorAtOnce)
{
    cpm::ParameterServer sut(server_side);
    sut.set_int("known", 1);

    EXPECT_THAT(error_of([] { cpm::parameter_int("unknown"); }), HasSubstr("does not know it"));
}

TEST_F(ParameterTest, TypeMismatchNamesTheParameterAndBothTypes)
{
    cpm::ParameterServer sut(server_side);
    sut.set_double("wheelbase", 0.15);

    const std::string message = error_of([] { cpm::parameter_string("wheelbase"); });

    EXPECT_THAT(message, HasSubstr("'wheelbase'"));
    EXPECT_THAT(message, HasSubstr("double"));
    EXPECT_THAT(message, HasSubstr("string"));
}

TEST_F(ParameterTest, ChangedValueReachesAClientThatAsksAgain)
{
    cpm::ParameterServer sut(server_side);
    sut.set_double("gain", 1.0);
    ASSERT_EQ(cpm::parameter_double("gain"), 1.0);

    sut.set_double("gain", 2.5);

    EXPECT_TRUE(cpm_test::wait_until([] { return cpm::parameter_double("gain") == 2.5; }));
}

TEST_F(ParameterTest, JsonFileTypesComeFromValuesOrExplicitTypes)
{
    cpm::ParameterServer sut(server_side);
    const size_t n = sut.load_json_file(write_file(R"({"on": false, "count": 7, "big": 5000000000, "rate": 50.0,
        "map": "corridor", "ids": [1, 3, 7], "gains": [0.5, 1], "forced": {"type": "uint64", "value": 3}})"));

    EXPECT_EQ(n, 8u);
    EXPECT_EQ(cpm::parameter_bool("on"), false);
    EXPECT_EQ(cpm::parameter_int("count"), 7);
    EXPECT_EQ(cpm::parameter_uint64_t("big"), 5'000'000'000ull);
    EXPECT_EQ(cpm::parameter_double("rate"), 50.0);
    EXPECT_EQ(cpm::parameter_string("map"), "corridor");
    EXPECT_EQ(cpm::parameter_ints("ids"), (std::vector<int32_t>{1, 3, 7}));
    EXPECT_EQ(cpm::parameter_doubles("gains"), (std::vector<double>{0.5, 1.0}));
    EXPECT_EQ(cpm::parameter_uint64_t("forced"), 3u);
}

TEST_F(ParameterTest, BadFilesAreErrorsNamingFileAndPlaceAndLoadNothing)
{
    cpm::ParameterServer sut(server_side);
    const std::string broken = write_file("{\"a\": 1,");
    const std::string bad_value = write_file(R"({"a": 1, "b": {"type": "int", "value": "x"}})");
    const std::string mixed = write_file(R"({"a": [1, "two"]})");

    EXPECT_THAT(error_of([&] { sut.load_json_file(broken); }), HasSubstr("'" + broken + "': not valid JSON"));
    EXPECT_THAT(error_of([&] { sut.load_json_file(bad_value); }), HasSubstr("at /b"));
    EXPECT_THAT(error_of([&] { sut.load_json_file(mixed); }), HasSubstr("at /a"));
    EXPECT_THAT(error_of([&] { sut.load_json_file("/nonexistent.json"); }), HasSubstr("/nonexistent.json: cannot open the parameter file: no such file"));
    EXPECT_EQ(sut.size(), 0u) << "a file with an error must load nothing";
}

TEST_F(ParameterTest, YamlFileReadsTheSameTypesAndKeepsQuotedTextAsText)
{
    cpm::ParameterServer sut(server_side);
    const size_t n = sut.load_file(write_file("on: true\ncount: 7\nrate: 50.5\nmap: corridor\nversion: \"12\"\n"
                                              "ids: [1, 3, 7]\ngains: [0.5, 1]\nforced:\n  type: uint64\n  value: 3\n",
                                              ".yaml"));

    EXPECT_EQ(n, 8u);
    EXPECT_EQ(cpm::parameter_bool("on"), true);
    EXPECT_EQ(cpm::parameter_int("count"), 7);
    EXPECT_EQ(cpm::parameter_double("rate"), 50.5);
    EXPECT_EQ(cpm::parameter_string("map"), "corridor");
    EXPECT_EQ(cpm::parameter_string("version"), "12");
    EXPECT_EQ(cpm::parameter_ints("ids"), (std::vector<int32_t>{1, 3, 7}));
    EXPECT_EQ(cpm::parameter_doubles("gains"), (std::vector<double>{0.5, 1.0}));
    EXPECT_EQ(cpm::parameter_uint64_t("forced"), 3u);
}

TEST_F(ParameterTest, BrokenYamlNamesFileAndLine)
{
    cpm::ParameterServer sut(server_side);
    const std::string broken = write_file("a: 1\nb: [1, 2\nc: 3\n", ".yml");

    const std::string message = error_of([&] { sut.load_file(broken); });

    EXPECT_THAT(message, HasSubstr("'" + broken + "' line "));
    EXPECT_EQ(sut.size(), 0u);
}

TEST_F(ParameterTest, IntListsAreNeverTruncated)
{
    cpm::ParameterServer sut(server_side);
    const std::string explicit_ints = write_file(R"({"ids": {"type": "ints", "value": [1, 5000000000]}})");
    EXPECT_THAT(error_of([&] { sut.load_json_file(explicit_ints); }), HasSubstr("at /ids"));

    sut.load_json_file(write_file(R"({"big": [1, 5000000000]})"));

    EXPECT_EQ(cpm::parameter_doubles("big"), (std::vector<double>{1.0, 5e9}));
}
