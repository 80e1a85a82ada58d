// A run's report drawn from a recording made here, sample by sample: the gates of the world are
// judged on each car's true path (a car through every gate's centre passes all of them, a car
// beside the course none), and the page says so.
#include <cpm/lab/Report.hpp>
#include <cpm/rtdb/IdlDecoder.hpp>
#include <cpm/rtdb/Recording.hpp>
#include <cpm/vehicle/World.hpp>

#include <cpm_test/TempDir.hpp>
#include <cpm_test/SourceDir.hpp>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>

using namespace cpm;
namespace fs = std::filesystem;

namespace {

const std::string kGates = cpm_test::source_dir() + "/scenarios/maps/gates.json";

/// The true poses of a car driving 0.5 m/s along the straight legs between `points`, every 20 ms
/// of lab time from 0.
std::vector<std::array<double, 4>> drive(const std::vector<std::pair<double, double>>& points)
{
    std::vector<std::array<double, 4>> path;  // t, x, y, yaw
    double t = 0;
    for (size_t i = 1; i < points.size(); ++i) {
        const auto [x0, y0] = points[i - 1];
        const auto [x1, y1] = points[i];
        const double length = std::hypot(x1 - x0, y1 - y0), yaw = std::atan2(y1 - y0, x1 - x0);
        for (double s = 0; s < length; s += 0.01, t += 0.02) path.push_back({t, x0 + (x1 - x0) * s / length, y0 + (y1 - y0) * s / length, yaw});
    }
    return path;
}

}  // namespace

TEST(Report, JudgesTheWorldsGatesOnEachCarsTruePath)
{
    cpm_test::TempDir dir;
    const auto world = vehicle::World::load(kGates);
    ASSERT_EQ(world.gates().size(), 3u);
    std::vector<std::pair<double, double>> through{{0, 0}};
    for (const auto& g : world.gates()) {
        const auto *l = world.marker(g.left), *r = world.marker(g.right);
        through.emplace_back((l->x + r->x) / 2, (l->y + r->y) / 2);
    }
    through.emplace_back(through.back().first + 1.5, through.back().second);

    const auto* types = rtdb::IdlDecoder::lab_types();
    ASSERT_NE(types, nullptr);
    {
        rtdb::Store store;
        rtdb::RecordingWriter writer(dir.file("recording.db"), {.name = "gates"});
        uint64_t commit = 1'000'000'000'000'000'000ull;  // the history's real clock
        for (const auto& [id, points] : std::vector<std::pair<int, std::vector<std::pair<double, double>>>>{
                 {6, through}, {7, {{0, 1.5}, {11, 1.5}}}}) {
            const rtdb::Oid oid = store.add_object({.topic = "vehicleObservation", .key = std::to_string(id), .type_name = "VehicleObservation"});
            writer.object_added(*store.info(oid));
            for (const auto& [t, x, y, yaw] : drive(points)) {
                const auto ns = uint64_t(t * 1e9);
                const auto payload = types->encode("VehicleObservation", {{"header", {{"create_stamp", {{"nanoseconds", ns}}}, {"valid_after_stamp", {{"nanoseconds", ns}}}}},
                                                                          {"vehicle_id", id},
                                                                          {"pose", {{"x", x}, {"y", y}, {"yaw", yaw}}}});
                const rtdb::Incoming in{ns, ns, commit, payload.data(), payload.size(), 0};
                writer.sample_committed(oid, in, store.commit(oid, in, commit));
                commit += 1'000'000;
            }
        }
        writer.close();
    }
    std::ofstream(dir.file("summary.json")) << nlohmann::json{{"name", "gates"}, {"time", "simulated"}, {"world", kGates}, {"ok", true}}.dump();

    const auto report = lab::make_report(dir.path.string());
    const auto& cars = report.figures["cars"];
    ASSERT_TRUE(cars.contains("6") && cars.contains("7")) << report.figures.dump(2);
    EXPECT_EQ(cars["6"]["gates_passed"], 3) << cars["6"].dump(2);
    for (const auto& g : cars["6"]["gates"]) {
        EXPECT_EQ(g["passed"], true);
        EXPECT_NEAR(g["offset_m"].get<double>(), 0.0, 0.02) << "through the centre: " << g.dump();
    }
    EXPECT_EQ(cars["7"]["gates_passed"], 0) << cars["7"].dump(2);
    std::ifstream page(report.html);
    const std::string html((std::istreambuf_iterator<char>(page)), std::istreambuf_iterator<char>());
    EXPECT_NE(html.find("<th>gates passed</th>"), std::string::npos);
    EXPECT_NE(html.find("<td>3 of 3</td>"), std::string::npos) << "car 6";
    EXPECT_NE(html.find("<td class=\"bad\">0 of 3</td>"), std::string::npos) << "car 7";
    // Lab-time stamps against real-clock commits: rates per lab second, no delay across clocks.
    EXPECT_NEAR(report.figures["topics"]["vehicleObservation"]["rate_hz"].get<double>(), 100, 3) << "two cars at 50 Hz of lab time";
    EXPECT_FALSE(report.figures["topics"]["vehicleObservation"].contains("delay_ms_p50"));
}

TEST(Report, ARecordingWithoutSamplesOrDamagedIsNamedNotHandedToGnuplot)
{
    cpm_test::TempDir dir;
    {
        rtdb::RecordingWriter writer(dir.file("recording.db"), {.name = "cut"});
        writer.close();
    }
    std::ofstream(dir.file("summary.json")) << nlohmann::json{{"name", "cut"}, {"ok", true}}.dump();
    auto error_of = [&] {
        try {
            (void)lab::make_report(dir.path.string());
        } catch (const std::exception& e) {
            return std::string(e.what());
        }
        return std::string("no error");
    };
    const std::string empty = error_of();
    EXPECT_NE(empty.find(dir.file("recording.db") + " holds no samples"), std::string::npos) << empty;
    fs::resize_file(dir.file("recording.db"), 4096);  // cut short, as by a full disk or a kill
    const std::string cut = error_of();
    EXPECT_NE(cut.find(dir.file("recording.db")), std::string::npos) << cut;
    for (const auto& e : {empty, cut}) EXPECT_EQ(e.find("gnuplot"), std::string::npos) << e;
}
