// bench_ips: the positioning system (IPS). Per-frame cost of ips_node's work at 1280×1024 for 8
// and 20 cars against plain cv::aruco::detectMarkers (OpenCV's defaults) on the same frames in
// the same process, interleaved; accuracy against the renderer's truth over the whole map,
// clean and with sensor noise and blur; exposure → vehicleObservation latency with real
// processes (8 simulated cars, the overhead camera_sim, ips_node) at 50 Hz.
#include "bench_common.hpp"

#include <cpm/CommandLine.hpp>
#include <cpm/aruco/Overhead.hpp>
#include <cpm/init.hpp>

#include <opencv2/aruco.hpp>
#include <opencv2/core/utility.hpp>

#include <nlohmann/json.hpp>

#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <map>
#include <random>
#include <thread>

using namespace cpm;
using Clock = std::chrono::steady_clock;

namespace {

std::string g_root;

aruco::Camera ceiling() { return aruco::Camera::load(g_root + "/scenarios/cameras/ceiling_1280x1024.yaml", aruco::CameraPlacement::overhead); }
vehicle::World lab_floor() { return vehicle::World::load(g_root + "/scenarios/maps/lab_floor.json"); }

double us_since(Clock::time_point t0) { return std::chrono::duration<double, std::micro>(Clock::now() - t0).count(); }

/// `n` cars at seeded poses over the lab (0.3 .. 4.2 × 0.3 .. 3.7 m), their reference points at
/// least 0.5 m apart.
std::vector<aruco::OverheadCar> cars_at_random(int n, std::mt19937& rng)
{
    std::uniform_real_distribution<double> x(0.3, 4.2), y(0.3, 3.7), yaw(-M_PI, M_PI);
    std::vector<aruco::OverheadCar> cars;
    while (int(cars.size()) < n) {
        const vehicle::Pose p{x(rng), y(rng), yaw(rng)};
        bool apart = true;
        for (const auto& c : cars) apart = apart && std::hypot(c.pose.x - p.x, c.pose.y - p.y) >= 0.5;
        if (apart) cars.push_back({int(cars.size()) + 1, p});
    }
    return cars;
}

// ---- 1. per-frame cost ---------------------------------------------------------------------------

void frame_cost(int n_cars)
{
    const auto camera = ceiling();
    const auto world = lab_floor();
    aruco::OverheadRenderer renderer(world, camera);
    aruco::OverheadLocator ips(world, camera);
    std::mt19937 rng{uint32_t(n_cars)};
    std::vector<cv::Mat> frames(120);
    for (auto& f : frames) renderer.render(cars_at_random(n_cars, rng), f);
    const auto dict = cv::aruco::getPredefinedDictionary(cv::aruco::DICT_4X4_50);
    const auto params = cv::aruco::DetectorParameters::create();
    std::vector<int> ids;
    std::vector<std::vector<cv::Point2f>> corners;
    std::vector<double> plain, node;
    size_t found = 0;
    for (size_t i = 0; i < frames.size(); ++i) {
        const bool warm = i >= 20;
        auto t0 = Clock::now();
        cv::aruco::detectMarkers(frames[i], dict, corners, ids, params);
        if (warm) plain.push_back(us_since(t0));
        t0 = Clock::now();
        const auto view = ips.locate(frames[i]);
        if (warm) node.push_back(us_since(t0));
        found += view.cars.size();
    }
    const auto p = bench::stats_of(plain), o = bench::stats_of(node);
    bench::print_header("1. per-frame cost, 1280×1024 mono, " + std::to_string(n_cars) + " cars and 6 floor markers, one thread (µs); " +
                        std::to_string(found) + " of " + std::to_string(frames.size() * size_t(n_cars)) + " cars found");
    bench::print_row("plain detectMarkers (OpenCV's defaults)", p);
    bench::print_row("ips_node's work: detect + sub-pixel + poses", o);
    const double hz = 1e6 / o.p50;
    std::printf("ips / plain p50 %.3f; %.1f frames/s on one core (target for 20 cars: 50 Hz: %s)\n", o.p50 / p.p50, hz,
                n_cars < 20 ? "-" : hz >= 50 ? "met" : "NOT met");
    const std::string what = "frame work, " + std::to_string(n_cars) + " cars, 1280x1024";
    bench::record_latency("ips", what, o, "plain detectMarkers", p);
    if (n_cars >= 20) bench::record({"ips", "frames/s on one core, 20 cars", "Hz", hz, "", 0, ">= 50 Hz", int(hz >= 50)});
}

// ---- 2. accuracy -----------------------------------------------------------------------------------

void accuracy(const char* label, double noise, int blur)
{
    const auto camera = ceiling();
    const auto world = lab_floor();
    aruco::OverheadRenderer renderer(world, camera, aruco::RenderOptions{.noise_sigma = noise, .blur = blur, .seed = 7});
    aruco::OverheadLocator ips(world, camera);
    std::mt19937 rng(3);
    std::vector<double> metres, degrees;
    int drawn = 0;
    cv::Mat frame;
    for (int f = 0; f < 100; ++f) {
        const auto cars = cars_at_random(8, rng);
        renderer.render(cars, frame);
        std::map<int, aruco::LocatedCar> found;
        for (const auto& c : ips.locate(frame).cars) found[c.vehicle_id] = c;
        for (const auto& car : cars) {
            ++drawn;
            auto it = found.find(car.vehicle_id);
            if (it == found.end()) continue;
            metres.push_back(std::hypot(it->second.x - car.pose.x, it->second.y - car.pose.y) * 1000);
            degrees.push_back(std::abs(std::remainder(it->second.yaw - car.pose.yaw, 2 * M_PI)) * 180 / M_PI);
        }
    }
    const auto m = bench::stats_of(metres), d = bench::stats_of(degrees);
    const double rate = 100.0 * double(metres.size()) / drawn;
    std::printf("%-26s found %5.1f %%  position mm p50 %.2f p99 %.2f max %.2f  heading ° p50 %.2f p99 %.2f (targets 1 cm, 1°: %s)\n", label,
                rate, m.p50, m.p99, m.max, d.p50, d.p99, m.p99 <= 10 && d.p99 <= 1 ? "met" : "NOT met");
    bench::record({"ips", std::string("position error p99, ") + label, "mm", m.p99, "", 0, "<= 10 mm", int(m.p99 <= 10)});
    bench::record({"ips", std::string("heading error p99, ") + label, "°", d.p99, "", 0, "<= 1°", int(d.p99 <= 1)});
    bench::record({"ips", std::string("cars found, ") + label, "%", rate, "", 0, "", -1});
}

// ---- 3. latency in the lab -------------------------------------------------------------------------

void lab_latency()
{
    const std::string bin = cpm::executable_dir();
    const std::string camera = g_root + "/scenarios/cameras/ceiling_1280x1024.yaml", world = g_root + "/scenarios/maps/lab_floor.json";
    const std::string out = "/tmp/bench_ips_node_" + std::to_string(::getpid()) + ".out";
    auto cars = bench::spawn({bin + "/cpm", "vehicle", "sim", "--id", "1", "--count", "8", "--lanes", g_root + "/scenarios/lanes/intersection.json",
                              "--truth_topic", "vehicleObservationTruth"},
                             {}, "/dev/null", "/dev/null");
    auto overhead = bench::spawn({bin + "/camera_sim", "--overhead", "--camera", camera, "--map", world}, {}, "/dev/null", "/dev/null");
    std::this_thread::sleep_for(std::chrono::seconds(2));
    auto node = bench::spawn({bin + "/ips_node", "--camera", camera, "--world", world}, {}, out, "/dev/null");
    std::this_thread::sleep_for(std::chrono::seconds(12));
    for (auto* p : {&node, &overhead, &cars}) {
        p->signal(SIGINT);
        bench::wait_child(*p, 10);
    }
    std::ifstream in(out);
    std::string line, last;
    while (std::getline(in, line)) {
        if (!line.empty() && line[0] == '{') last = line;
    }
    std::remove(out.c_str());
    const auto j = nlohmann::json::parse(last, nullptr, false);
    if (!j.is_object()) {
        std::printf("\n3. latency: ips_node printed no statistics\n");
        return;
    }
    const double p50 = j["latency_ms_p50"], p99 = j["latency_ms_p99"];
    std::printf("\n3. in the lab: 8 cars, camera_sim --overhead (50 Hz) → ips_node, 12 s, exposure to vehicleObservation published\n");
    std::printf("frames %d, dropped %d, observations %d, processing p50 %.2f ms p99 %.2f ms; latency p50 %.2f ms, p99 %.2f ms\n",
                int(j["frames"]), int(j["dropped"]), int(j["observations"]), double(j["processing_ms_p50"]), double(j["processing_ms_p99"]),
                p50, p99);
    bench::record({"ips", "exposure -> vehicleObservation latency p50, 8 cars", "ms", p50, "", 0, "", -1});
    bench::record({"ips", "exposure -> vehicleObservation latency p99, 8 cars", "ms", p99, "", 0, "", -1});
    bench::record({"ips", "frames dropped of 600, 8 cars", "frames", double(j["dropped"]), "", 0, "", -1});
}

const char* kHelp =
    "usage: bench_ips [--root DIR] [--dds_domain D]\n"
    "The positioning system: per-frame cost for 8 and 20 cars against plain OpenCV on the same frames,\n"
    "accuracy against ground truth clean and degraded, exposure → vehicleObservation latency with real processes.\n"
    "  --root DIR  the cpm source tree (its scenarios/); default: the one this was built from\n";

int run(int argc, char** argv)
{
    const auto flags = cpm::cli::parse_flags(argc, argv, {{"--root", true}}, "bench_ips");
    g_root = flags.get("--root", CPM_SOURCE_DIR);
    cv::setNumThreads(1);
    bench::print_machine("OpenCV " + std::string(CV_VERSION) + ", cv::setNumThreads(1); frames drawn by camera_sim --overhead's renderer");
    cpm::init(argc, argv);
    frame_cost(8);
    frame_cost(20);
    bench::print_header("2. accuracy, 100 frames of 8 cars at random over the lab, against the renderer's truth");
    accuracy("clean", 0, 0);
    accuracy("noise σ 6", 6, 0);
    accuracy("blur 3 px + noise σ 6", 6, 3);
    lab_latency();
    return 0;
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "bench_ips", kHelp, run); }
