// cpm aruco detect, cpm camera render | calibrate: the perception library on files.
#include "Command.hpp"

#include <cpm/Error.hpp>
#include <cpm/aruco/Calibration.hpp>
#include <cpm/aruco/DetectorFlags.hpp>
#include <cpm/aruco/Images.hpp>
#include <cpm/aruco/Overhead.hpp>
#include <cpm/aruco/Renderer.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/aruco/GateCourse.hpp>
#include <cpm/topics.hpp>
#include <cpm/vehicle/VehicleModel.hpp>

#include <CameraFrame.h>
#include <VehicleObservation.h>

#include <nlohmann/json.hpp>

#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <thread>
#include <string>
#include <vector>

namespace {

using cpm::tools::UsageError;

const std::string kDetectHelp = std::string(
    "usage: cpm aruco detect IMAGE... --camera FILE [--world FILE] [--marker-size M] [--dictionary NAME] [--json]\n"
    "\n"
    "Finds the ArUco markers in still images with the same code as aruco_node: ids, corners (px)\n"
    "and, when the marker's size is known, its pose in the car frame through the camera's\n"
    "mounting (x forward, y left, yaw of the marker's face; distance from the camera).\n"
    "--json prints one line per image: {\"image\": …, \"markers\": [{\"id\": …, \"corners\": [[u, v] ×4],\n"
    "\"x\": …, \"y\": …, \"yaw\": …, \"distance\": …}]} (pose null when the size is unknown).\n"
    "\n") + cpm::aruco::kDetectorFlagsHelp;

int aruco_detect(const std::vector<std::string>& args)
{
    auto flags = cpm::aruco::detector_flags();
    flags.push_back({"--json", false});
    auto parsed = cpm::tools::parse_args(args, flags, "cpm aruco detect");
    if (parsed.positional.empty()) throw UsageError("cpm aruco detect: give one or more images");
    auto setup = cpm::aruco::detector_setup(parsed, "cpm aruco detect");
    // Every image is read before any is searched: a wrong path fails at once.
    std::vector<cv::Mat> images;
    for (const auto& path : parsed.positional) images.push_back(cpm::aruco::read_camera_image(path, setup.camera));
    cpm::aruco::MarkerDetector detector(setup.camera, setup.options, setup.sizes);
    const bool json = parsed.has("--json");
    for (size_t i = 0; i < images.size(); ++i) {
        auto markers = detector.observe(images[i]);
        std::sort(markers.begin(), markers.end(), [](const auto& a, const auto& b) { return a.id < b.id; });
        if (json) {
            nlohmann::json line{{"image", parsed.positional[i]}, {"markers", nlohmann::json::array()}};
            for (const auto& m : markers) {
                nlohmann::json corners = nlohmann::json::array();
                for (const auto& c : m.corners) corners.push_back({c.x, c.y});
                nlohmann::json entry{{"id", m.id}, {"corners", corners}};
                for (auto [name, value] : {std::pair{"x", m.x}, {"y", m.y}, {"yaw", m.yaw}, {"distance", m.distance}}) {
                    entry[name] = m.has_pose ? nlohmann::json(value) : nlohmann::json(nullptr);
                }
                line["markers"].push_back(entry);
            }
            std::printf("%s\n", line.dump().c_str());
            continue;
        }
        std::printf("%s: %zu marker(s)\n", parsed.positional[i].c_str(), markers.size());
        for (const auto& m : markers) {
            if (m.has_pose) {
                std::printf("  id %d: x %.3f m, y %.3f m, yaw %.1f°, distance %.3f m\n", m.id, m.x, m.y, m.yaw * 180 / M_PI, m.distance);
            } else {
                std::printf("  id %d: corners (%.1f, %.1f) (%.1f, %.1f) (%.1f, %.1f) (%.1f, %.1f); size unknown, no pose\n", m.id,
                            m.corners[0].x, m.corners[0].y, m.corners[1].x, m.corners[1].y, m.corners[2].x, m.corners[2].y,
                            m.corners[3].x, m.corners[3].y);
            }
        }
    }
    return 0;
}

const char* const kRenderHelp =
    "usage: cpm camera render --world FILE --camera FILE --pose X,Y,YAW --out FRAME.png\n"
    "                         [--noise SIGMA] [--blur K] [--seed S] [--dictionary NAME]\n"
    "       cpm camera render --overhead --world FILE --camera FILE [--cars ID:X,Y,YAW;...] --out FRAME.png [...]\n"
    "\n"
    "Renders one frame of the synthetic camera (what camera_sim publishes) for a car at the\n"
    "pose (rear axle, world frame: metres, radians) and lists the markers drawn, as they truly\n"
    "are in the car frame. --overhead: the lab's positioning camera instead (camera_sim\n"
    "--overhead), its pose in the map from the camera file, the world's floor markers and the\n"
    "cars of --cars (each wearing its roof marker of the world), with each marker's corners in px.\n";

/// `--cars "1:1.0,1.2,0.3;2:3,2.5,2"`: cars by id and pose.
std::vector<cpm::aruco::OverheadCar> parse_cars(const std::string& text)
{
    std::vector<cpm::aruco::OverheadCar> cars;
    size_t start = 0;
    while (start < text.size()) {
        const size_t end = std::min(text.find(';', start), text.size());
        const std::string item = text.substr(start, end - start);
        const size_t colon = item.find(':');
        if (colon == std::string::npos) throw UsageError("cpm camera render: --cars: '" + item + "': expected ID:X,Y,YAW");
        const int id = int(cpm::cli::parse_integer("--cars", item.substr(0, colon), 1, 255));
        cars.push_back({id, cpm::vehicle::parse_pose("--cars", item.substr(colon + 1))});
        start = end + 1;
    }
    return cars;
}

int overhead_render(const cpm::tools::ParsedArgs& parsed, const cpm::aruco::RenderOptions& options)
{
    if (parsed.has("--pose")) throw UsageError("cpm camera render: --overhead draws the cars of --cars; leave out --pose");
    cpm::aruco::OverheadRenderer renderer(cpm::vehicle::World::load(parsed.get("--world")),
                                          cpm::aruco::Camera::load(parsed.get("--camera"), cpm::aruco::CameraPlacement::overhead), options);
    std::vector<cpm::aruco::OverheadTruth> truth;
    cv::Mat frame;
    renderer.render(parse_cars(parsed.get("--cars")), frame, &truth);
    cpm::aruco::write_image(parsed.get("--out"), frame);
    std::printf("%s: %d×%d, %zu marker(s) drawn\n", parsed.get("--out").c_str(), frame.cols, frame.rows, truth.size());
    for (const auto& t : truth) {
        std::printf("  id %d (%s): corners (%.1f, %.1f) (%.1f, %.1f) (%.1f, %.1f) (%.1f, %.1f) px, side %.1f px%s\n", t.id,
                    t.vehicle_id ? ("car " + std::to_string(t.vehicle_id)).c_str() : "floor", t.corners[0].x, t.corners[0].y, t.corners[1].x,
                    t.corners[1].y, t.corners[2].x, t.corners[2].y, t.corners[3].x, t.corners[3].y, t.side_px,
                    t.whole_in_view ? "" : " (partly outside the image)");
    }
    return 0;
}

int camera_render(const std::vector<std::string>& args)
{
    auto parsed = cpm::tools::parse_flags(args,
                                          {{"--world", true}, {"--camera", true}, {"--pose", true}, {"--out", true}, {"--noise", true},
                                           {"--blur", true}, {"--seed", true}, {"--dictionary", true}, {"--overhead", false}, {"--cars", true}},
                                          "cpm camera render");
    const bool overhead = parsed.has("--overhead");
    for (const char* flag : {"--world", "--camera", "--pose", "--out"}) {
        if (!parsed.has(flag) && !(overhead && std::string(flag) == "--pose")) {
            throw UsageError(std::string("cpm camera render: ") + flag + " is required");
        }
    }
    if (!overhead && parsed.has("--cars")) throw UsageError("cpm camera render: --cars is for --overhead; the car's camera takes --pose");
    cpm::aruco::RenderOptions options;
    options.noise_sigma = cpm::cli::parse_number("--noise", parsed.get("--noise", "0"), 0, 128);
    options.blur = int(cpm::cli::parse_integer("--blur", parsed.get("--blur", "0"), 0, 31));
    options.seed = uint32_t(cpm::cli::parse_integer("--seed", parsed.get("--seed", "1"), 0, UINT32_MAX));
    options.dictionary = parsed.get("--dictionary", "DICT_4X4_50");
    if (overhead) return overhead_render(parsed, options);
    const auto pose = cpm::vehicle::parse_pose("--pose", parsed.get("--pose"));
    cpm::aruco::Renderer renderer(cpm::vehicle::World::load(parsed.get("--world")), cpm::aruco::Camera::load(parsed.get("--camera")), options);
    std::vector<cpm::aruco::RenderedMarker> truth;
    cv::Mat frame = renderer.render(pose, &truth);
    cpm::aruco::write_image(parsed.get("--out"), frame);
    std::printf("%s: %d×%d, %zu marker(s) drawn\n", parsed.get("--out").c_str(), frame.cols, frame.rows, truth.size());
    for (const auto& t : truth) {
        std::printf("  id %d: x %.3f m, y %.3f m, yaw %.1f°, distance %.3f m, side %.1f px%s\n", t.id, t.x, t.y, t.yaw * 180 / M_PI,
                    t.distance, t.side_px, t.whole_in_view ? "" : " (partly outside the image)");
    }
    return 0;
}

const char* const kLocateHelp =
    "usage: cpm camera locate --camera FILE --world FILE --image IMAGE [--out FILE] [--max-residual PX]\n"
    "\n"
    "Finds the overhead camera's pose in the map from one image of it: the world's floor_markers\n"
    "(at least 2 in view) at their known places, through solvePnP refined over every corner. Writes\n"
    "the camera file (--out, default the camera file itself) with world_x, world_y, world_z,\n"
    "world_rotation and world_residual_px. When the file already held a pose, says how far the\n"
    "camera moved since. A residual over --max-residual (default 2 px) writes nothing and exits 1:\n"
    "the floor does not look as the world says (a marker moved, a wrong size or id).\n";

int camera_locate(const std::vector<std::string>& args)
{
    auto parsed = cpm::tools::parse_flags(args, {{"--camera", true}, {"--world", true}, {"--image", true}, {"--out", true}, {"--max-residual", true}},
                                          "cpm camera locate");
    for (const char* flag : {"--camera", "--world", "--image"}) {
        if (!parsed.has(flag)) throw UsageError(std::string("cpm camera locate: ") + flag + " is required");
    }
    const double max_residual = cpm::cli::parse_number("--max-residual", parsed.get("--max-residual", "2"), 0.01, 100);
    auto camera = cpm::aruco::Camera::load(parsed.get("--camera"), cpm::aruco::CameraPlacement::lens_only);
    const auto world = cpm::vehicle::World::load(parsed.get("--world"));
    const cv::Mat image = cpm::aruco::read_camera_image(parsed.get("--image"), camera);
    const auto found = [&] {
        try {
            return cpm::aruco::locate_camera(camera, world, image);
        } catch (const cpm::Error& e) {
            throw cpm::Error(parsed.get("--image") + " with " + parsed.get("--world") + ": " + e.what());
        }
    }();
    std::string used, unknown;
    for (int id : found.markers) used += " " + std::to_string(id);
    for (int id : found.unknown) unknown += " " + std::to_string(id);
    const auto& p = found.pose;
    const cv::Vec3d axis = p.rotation * cv::Vec3d(0, 0, 1);  // where the camera looks, in the map
    std::printf("floor markers used:%s%s\n", used.c_str(), unknown.empty() ? "" : ("; other markers seen:" + unknown).c_str());
    std::printf("camera at x %.4f m, y %.4f m, z %.4f m; looks %.2f° off straight down; residual %.3f px\n", p.position[0], p.position[1],
                p.position[2], std::acos(std::clamp(-axis[2], -1.0, 1.0)) * 180 / M_PI, p.residual_px);
    if (camera.overhead) {
        std::printf("moved since it was last located: %.1f mm, turned %.3f°\n", cv::norm(p.position - camera.overhead->position) * 1000,
                    cpm::aruco::rotation_angle(p.rotation, camera.overhead->rotation) * 180 / M_PI);
    }
    if (p.residual_px > max_residual) {
        throw cpm::Error(parsed.get("--image") + ": the floor markers fit the pose only to " + std::to_string(p.residual_px) +
                         " px (over " + std::to_string(max_residual) + "): does the floor look as " + parsed.get("--world") +
                         " says (a marker moved, a wrong size or id)? nothing written");
    }
    camera.overhead = p;
    const std::string out = parsed.get("--out", parsed.get("--camera"));
    camera.save(out);
    std::printf("wrote %s\n", out.c_str());
    return 0;
}

const char* const kCalibrateHelp =
    "usage: cpm camera calibrate --images DIR --board charuco:XxY,SQUARE,MARKER[,DICT] --out camera.yaml\n"
    "\n"
    "Calibrates a camera from photos of a ChArUco board (OpenCV's calibrateCameraCharuco): XxY\n"
    "squares of SQUARE metres with markers of MARKER metres (default dictionary DICT_4X4_50; Y\n"
    "odd). Take 10-20 photos from different angles and distances, the board filling a good part\n"
    "of the image. Writes the camera file with the camera matrix and distortion (mount_* zero:\n"
    "set them to where the camera sits on the car) and prints the reprojection error.\n";

int camera_calibrate(const std::vector<std::string>& args)
{
    auto parsed = cpm::tools::parse_flags(args, {{"--images", true}, {"--board", true}, {"--out", true}}, "cpm camera calibrate");
    for (const char* flag : {"--images", "--board", "--out"}) {
        if (!parsed.has(flag)) throw UsageError(std::string("cpm camera calibrate: ") + flag + " is required");
    }
    cpm::aruco::CharucoBoard board;
    try {
        board = cpm::aruco::CharucoBoard::parse(parsed.get("--board"));
    } catch (const cpm::Error& e) {
        throw UsageError(std::string("cpm camera calibrate: --board: ") + e.what());
    }
    const auto images = cpm::aruco::list_images(parsed.get("--images"));
    auto result = cpm::aruco::calibrate(images, board);
    for (const auto& s : result.skipped) std::fprintf(stderr, "skipped %s\n", s.c_str());
    result.camera.save(parsed.get("--out"));
    const auto& k = result.camera.camera_matrix;
    std::printf("calibrated from %d of %zu images: reprojection error %.3f px\n", result.images_used, images.size(), result.rms_error);
    std::printf("fx %.2f fy %.2f cx %.2f cy %.2f px; distortion k1 %.4f k2 %.4f p1 %.4f p2 %.4f k3 %.4f\n", k(0, 0), k(1, 1), k(0, 2),
                k(1, 2), result.camera.distortion[0], result.camera.distortion[1], result.camera.distortion[2], result.camera.distortion[3],
                result.camera.distortion[4]);
    std::printf("wrote %s (set mount_x/y/z/yaw/pitch to where the camera sits on the car)\n", parsed.get("--out").c_str());
    return 0;
}

const char* const kGatesHelp =
    "usage: cpm aruco gates --map FILE --id N [--timeout 120s] [--frame-out FRAME.png] [--dds_domain N]\n"
    "\n"
    "Watches car N's true pose (vehicleObservation) and prints each gate of the map as the car\n"
    "drives through it, with how far from the gate's centre and how much room was left to the\n"
    "nearer marker. Ends when every gate is passed (exit 0), or at the timeout or Ctrl-C (exit 1,\n"
    "naming the gates not passed). --frame-out saves the car's camera frame from 2 m before the\n"
    "first gate (its approach view), when the car has a camera.\n";

int aruco_gates(const std::vector<std::string>& args)
{
    auto parsed = cpm::tools::parse_flags(args, {{"--map", true}, {"--id", true}, {"--timeout", true}, {"--frame-out", true}},
                                          "cpm aruco gates");
    if (!parsed.has("--map")) throw UsageError("cpm aruco gates: --map FILE is required (the world with its gates)");
    if (!parsed.has("--id")) throw UsageError("cpm aruco gates: --id N is required (the car)");
    const auto world = cpm::vehicle::World::load(parsed.get("--map"));
    if (world.gates().empty()) throw cpm::Error(parsed.get("--map") + ": the map has no gates");
    const auto id = uint8_t(cpm::cli::parse_integer("--id", parsed.get("--id"), 1, 255));
    const uint64_t timeout = cpm::tools::parse_duration("--timeout", parsed.get("--timeout", "120s"));
    const cpm::vehicle::VehicleParameters car;
    cpm::ReaderAbstract<VehicleObservation> poses(cpm::topics::vehicle_observation.name,
                                                  {.keep_all = true, .vehicle_id = id});
    std::unique_ptr<cpm::ReaderAbstract<CameraFrame>> frames;
    if (parsed.has("--frame-out")) {
        frames = std::make_unique<cpm::ReaderAbstract<CameraFrame>>(cpm::topics::camera_frame.name,
                                                                    cpm::ReaderOptions{.history_depth = 4, .vehicle_id = id});
    }
    std::vector<cpm::aruco::PathPoint> path;
    size_t reported = 0;
    bool frame_saved = false;
    cpm::cli::stop_on_signals();
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::nanoseconds(timeout);
    std::printf("watching car %u for %zu gate(s) of %s\n", unsigned(id), world.gates().size(), parsed.get("--map").c_str());
    std::fflush(stdout);
    std::vector<cpm::aruco::GatePassage> passages;
    while (!cpm::cli::stop_requested() && std::chrono::steady_clock::now() < deadline) {
        for (auto& o : poses.take()) {
            path.push_back({o.header().create_stamp().nanoseconds() * 1e-9, {o.pose().x(), o.pose().y(), o.pose().yaw()}});
        }
        if (frames && !frame_saved && !path.empty()) {
            // The first frame taken within 2 m of the first gate: its approach view.
            auto newest = frames->take();
            const auto& first = world.gates()[0];
            const auto *l = world.marker(first.left), *r = world.marker(first.right);
            const auto& at = path.back().pose;
            if (!newest.empty() && std::hypot((l->x + r->x) / 2 - at.x, (l->y + r->y) / 2 - at.y) <= 2.0) {
                const CameraFrame& f = newest.back();
                if (f.encoding() == "mono8" && f.data().size() == size_t(f.width()) * f.height()) {
                    cv::Mat image(int(f.height()), int(f.width()), CV_8UC1, const_cast<uint8_t*>(f.data().data()));
                    cpm::aruco::write_image(parsed.get("--frame-out"), image);
                    std::printf("saved the camera's view 2 m before gate 1 as %s\n", parsed.get("--frame-out").c_str());
                    std::fflush(stdout);
                }
                frame_saved = true;
            }
        }
        passages = cpm::aruco::gate_passages(world, path, car.width);
        while (reported < passages.size() && passages[reported].passed) {
            const auto& p = passages[reported];
            std::printf("gate %d passed: %.3f m %s of its centre, %.3f m from the nearer marker\n", p.gate + 1, std::abs(p.offset),
                        p.offset >= 0 ? "left" : "right", p.clearance);
            std::fflush(stdout);
            ++reported;
        }
        if (reported == passages.size()) return 0;
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    std::string missing;
    for (const auto& p : passages) {
        if (!p.passed) missing += (missing.empty() ? "" : ", ") + std::to_string(p.gate + 1);
    }
    std::fprintf(stderr, "cpm aruco gates: gate(s) %s not passed\n", missing.c_str());
    return 1;
}

}  // namespace

namespace cpm::tools {

std::vector<Command> aruco_commands()
{
    return {{.group = "aruco", .verb = "detect", .summary = "find ArUco markers and their poses in images (the code aruco_node runs)",
             .help = kDetectHelp.c_str(), .run = aruco_detect},
            {.group = "aruco", .verb = "gates", .summary = "print each gate of a map as a car drives through it", .help = kGatesHelp, .run = aruco_gates},
            {.group = "camera", .verb = "render", .summary = "render one frame of the synthetic camera from a pose", .help = kRenderHelp, .run = camera_render},
            {.group = "camera", .verb = "calibrate", .summary = "calibrate a camera from ChArUco board photos", .help = kCalibrateHelp, .run = camera_calibrate},
            {.group = "camera", .verb = "locate", .summary = "find the overhead camera's pose in the map from floor markers", .help = kLocateHelp,
             .run = camera_locate}};
}

}  // namespace cpm::tools
