// Real processes: cpm vehicle sim --camera (firmware_sim, vehicle_bridge, camera_sim) →
// aruco_node → arucoMarkers over DDS against the simulator's ground truth; the gate course
// driven by fsm_node; calibration from rendered ChArUco photos; each bad input.
#include <cpm/Participant.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/Writer.hpp>
#include <cpm/aruco/Calibration.hpp>
#include <cpm/aruco/Camera.hpp>
#include <cpm/aruco/GateCourse.hpp>
#include <cpm/aruco/Overhead.hpp>
#include <cpm/aruco/Renderer.hpp>
#include <cpm/get_time_ns.hpp>

#include <cpm_test/Dds.hpp>
#include <cpm_test/Isolation.hpp>
#include <cpm_test/Process.hpp>
#include <cpm_test/SourceDir.hpp>

#include <ArucoMarkers.h>
#include <CameraFrame.h>
#include <FsmStatus.h>
#include <VehicleObservation.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/videoio.hpp>

#include <cmath>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <optional>
#include <random>

using namespace std::chrono_literals;
using cpm_test::built_program;
using cpm_test::Process;

namespace {

const std::string kRoot = cpm_test::source_dir();
const std::string kCamera = kRoot + "/scenarios/cameras/sim_640x480.yaml";
const std::string kGates = kRoot + "/scenarios/maps/gates.json";

std::filesystem::path temp_dir(const std::string& name)
{
    auto dir = std::filesystem::temp_directory_path() / ("cpm_aruco_e2e_" + std::to_string(::getpid()) + "_" + name);
    std::filesystem::create_directories(dir);
    return dir;
}

/// The last line of a program's output that is a JSON object.
nlohmann::json last_json_line(const std::string& output)
{
    std::istringstream in(output);
    std::string line;
    nlohmann::json found;
    while (std::getline(in, line)) {
        if (!line.empty() && line[0] == '{') found = nlohmann::json::parse(line, nullptr, false);
    }
    return found;
}

struct Seen
{
    double x, y;
};

/// Where a world marker is in the frame of a car at `pose`.
Seen in_car_frame(const cpm::vehicle::Marker& m, const Pose2D& pose)
{
    const double dx = m.x - pose.x(), dy = m.y - pose.y(), c = std::cos(pose.yaw()), s = std::sin(pose.yaw());
    return {c * dx + s * dy, -s * dx + c * dy};
}

}  // namespace

TEST(ArucoEndToEnd, CameraSimThroughArucoNodeGivesTheTrueRelativePose)
{
    cpm::Participant participant(cpm_test::isolated_options());
    cpm::ReaderAbstract<ArucoMarkers> markers(participant, "arucoMarkers", {.keep_all = true});
    cpm::ReaderAbstract<VehicleObservation> observations(participant, "vehicleObservation", {.keep_all = true});
    Process car({built_program("cpm"), "vehicle", "sim", "--id", "5", "--map", kGates, "--camera", kCamera, "--start", "1.0,0.1,0.2"});
    Process node({built_program("aruco_node"), "--vehicle_id", "5", "--camera", kCamera, "--world", kGates});
    std::vector<ArucoMarkers> got;
    VehicleObservation truth;
    bool have_truth = false;
    ASSERT_TRUE(cpm_test::wait_until([&] {
        for (auto& m : markers.take()) got.push_back(m);
        for (auto& o : observations.take()) {
            truth = o;
            have_truth = true;
        }
        return got.size() >= 60 && have_truth;
    }, 30s, 20ms)) << got.size() << " ArucoMarkers\n" << node.output() << node.errors() << car.errors();
    node.kill(SIGINT);
    ASSERT_EQ(node.wait(10s), 0) << node.errors();
    car.kill(SIGINT);
    car.wait(10s);

    const auto world = cpm::vehicle::World::load(kGates);
    // The car stands still: every frame shows the first gate's markers where they truly are.
    int checked = 0;
    for (const auto& frame : got) {
        EXPECT_EQ(frame.vehicle_id(), 5);
        for (const auto& m : frame.markers()) {
            if (m.id() > 1) continue;  // the far gates' markers are small: not the nearby pose's test
            const auto expected = in_car_frame(*world.marker(m.id()), truth.pose());
            EXPECT_NEAR(m.pose().x(), expected.x, 0.03) << "marker " << m.id();
            EXPECT_NEAR(m.pose().y(), expected.y, 0.03) << "marker " << m.id();
            ++checked;
        }
    }
    EXPECT_GE(checked, 100);
    // Every processed frame gave one ArucoMarkers; the node's statistics say so.
    auto stats = last_json_line(node.output());
    ASSERT_TRUE(stats.is_object()) << node.output();
    EXPECT_GE(stats["frames"].get<int>(), int(got.size()));
    EXPECT_EQ(stats["bad_frames"].get<int>(), 0);
    EXPECT_GT(stats["latency_ms_p50"].get<double>(), 0.0);
}

TEST(ArucoEndToEnd, AFrameThatDisagreesWithTheCameraFileIsCountedAndTheNodeGoesOn)
{
    cpm::Participant participant(cpm_test::isolated_options());
    cpm::Writer<CameraFrame> frames(participant, "cameraFrame");
    cpm::ReaderAbstract<ArucoMarkers> markers(participant, "arucoMarkers", {.keep_all = true});
    Process node({built_program("aruco_node"), "--vehicle_id", "7", "--camera", kCamera, "--marker-size", "0.2"});
    ASSERT_TRUE(frames.wait_for_matched(1, 20s)) << node.errors();
    ASSERT_TRUE(markers.wait_for_matched(1, 20s)) << node.errors();
    auto send = [&](uint32_t w, uint32_t h, const std::string& encoding, size_t bytes) {
        CameraFrame f;
        f.vehicle_id(7);
        f.width(w);
        f.height(h);
        f.encoding(encoding);
        f.data(std::vector<uint8_t>(bytes, 128));
        f.header().create_stamp().nanoseconds(cpm::get_time_ns());
        ASSERT_TRUE(frames.write(f));
    };
    std::vector<ArucoMarkers> got;
    auto answered = [&](size_t n) {
        return cpm_test::wait_until([&] {
            for (auto& m : markers.take()) got.push_back(m);
            return got.size() >= n;
        }, 2s);
    };
    // First a good (empty) frame until the node answers: both sides have matched (a best-effort
    // sample written before the reader matched the writer is lost, and would not be counted).
    bool up = false;
    for (int i = 0; i < 20 && !up; ++i) {
        send(640, 480, "mono8", 640 * 480);
        up = answered(1);
    }
    ASSERT_TRUE(up) << node.errors();
    const size_t good_before = got.size();
    send(320, 240, "mono8", 320 * 240);    // wrong size
    std::this_thread::sleep_for(200ms);
    send(640, 480, "yuv422", 640 * 480 * 2);  // unknown encoding
    std::this_thread::sleep_for(200ms);
    send(640, 480, "mono8", 100);          // too few bytes
    std::this_thread::sleep_for(200ms);
    send(640, 480, "mono8", 640 * 480);    // a good (empty) frame: the node still answers
    EXPECT_TRUE(answered(good_before + 1)) << node.errors();
    EXPECT_TRUE(got.back().markers().empty());
    node.kill(SIGINT);
    ASSERT_EQ(node.wait(10s), 0) << node.errors();
    auto stats = last_json_line(node.output());
    // Each bad frame is counted as bad, or, when it piled up behind another while the node was
    // busy (a loaded machine), as dropped: the node takes the newest frame of a batch.
    const int dropped = stats["dropped"].get<int>();
    EXPECT_LE(dropped, 2) << node.output();  // the last good frame was answered
    EXPECT_GE(stats["bad_frames"].get<int>(), 1) << node.output();
    EXPECT_EQ(stats["bad_frames"].get<int>() + dropped, 3) << node.output();
    EXPECT_GE(stats["frames"].get<int>(), int(got.size()));  // one ArucoMarkers per good frame (best effort: some may not arrive)
    // Logged (at most once a second), naming what was wrong: the first bad frame that was not
    // dropped (the wrong size, unless it piled up).
    const std::string errors = node.errors();
    const size_t size = errors.find("320×240 px, the camera file says 640×480"), encoding = errors.find("encoding 'yuv422'"),
                 bytes = errors.find("100 bytes");
    EXPECT_TRUE(size != std::string::npos || encoding != std::string::npos || bytes != std::string::npos) << errors;
    if (dropped == 0) {
        EXPECT_NE(size, std::string::npos) << errors;
    }
}

TEST(ArucoEndToEnd, BadInputAtStartIsNamedWithANonZeroExit)
{
    const auto dir = temp_dir("bad");
    auto run = [](std::vector<std::string> argv) {
        Process p(std::move(argv));
        int code = p.wait(20s);
        return std::make_pair(code, p.errors() + p.output());
    };
    const std::string node = built_program("aruco_node"), cpm = built_program("cpm");
    // A missing camera file, a camera file without a field, an unknown dictionary.
    auto [c1, e1] = run({node, "--vehicle_id", "5", "--camera", "/nonexistent/cam.yaml"});
    EXPECT_NE(c1, 0);
    EXPECT_NE(e1.find("/nonexistent/cam.yaml: cannot open the camera file: no such file"), std::string::npos) << e1;
    const auto partial = (dir / "partial.yaml").string();
    std::ofstream(partial) << "%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\n";
    auto [c2, e2] = run({node, "--vehicle_id", "5", "--camera", partial});
    EXPECT_NE(c2, 0);
    EXPECT_NE(e2.find(partial + ": missing field camera_matrix"), std::string::npos) << e2;
    auto [c3, e3] = run({node, "--vehicle_id", "5", "--camera", kCamera, "--dictionary", "DICT_5X5_51"});
    EXPECT_NE(c3, 0);
    EXPECT_NE(e3.find("unknown dictionary 'DICT_5X5_51'"), std::string::npos) << e3;
    // A missing device, video or image folder; a folder without images.
    auto [c4, e4] = run({node, "--vehicle_id", "5", "--camera", kCamera, "--device", "/dev/video99"});
    EXPECT_NE(c4, 0);
    EXPECT_NE(e4.find("/dev/video99: no such device"), std::string::npos) << e4;
    auto [c5, e5] = run({node, "--vehicle_id", "5", "--camera", kCamera, "--video", "/nonexistent/drive.avi"});
    EXPECT_NE(c5, 0);
    EXPECT_NE(e5.find("/nonexistent/drive.avi: no such video file"), std::string::npos) << e5;
    auto [c6, e6] = run({node, "--vehicle_id", "5", "--camera", kCamera, "--images", dir.string()});
    EXPECT_NE(c6, 0);
    EXPECT_NE(e6.find(dir.string() + ": no images"), std::string::npos) << e6;
    // The simulated clock: frames from the topic only; --rate is the camera's rate there.
    auto [c9, e9] = run({node, "--vehicle_id", "5", "--camera", kCamera, "--images", dir.string(), "--simulated_time"});
    EXPECT_EQ(c9, 2);
    EXPECT_NE(e9.find("--simulated_time takes frames from the cameraFrame topic only; --images is read in real time"), std::string::npos) << e9;
    auto [c10, e10] = run({node, "--vehicle_id", "5", "--camera", kCamera, "--rate", "15"});
    EXPECT_EQ(c10, 2);
    EXPECT_NE(e10.find("--rate is the camera's rate on the simulated clock; it needs --simulated_time"), std::string::npos) << e10;
        // cpm aruco detect: an unreadable image, and one whose size is not the camera's.
    const auto not_image = (dir / "not_an_image.png").string();
    std::ofstream(not_image) << "text";
    auto [c7, e7] = run({cpm, "aruco", "detect", not_image, "--camera", kCamera});
    EXPECT_NE(c7, 0);
    EXPECT_NE(e7.find(not_image + ": cannot read the image"), std::string::npos) << e7;
    const auto small = (dir / "small.png").string();
    cpm::aruco::write_image(small, cv::Mat(100, 120, CV_8UC1, cv::Scalar(0)));
    auto [c8, e8] = run({cpm, "aruco", "detect", small, "--camera", kCamera});
    EXPECT_NE(c8, 0);
    EXPECT_NE(e8.find(small + ": 120×100 px, but the camera file says 640×480"), std::string::npos) << e8;
    std::filesystem::remove_all(dir);
}

TEST(ArucoEndToEnd, ImagesReplayedFromAFolderGiveOneArucoMarkersEach)
{
    const auto dir = temp_dir("replay");
    cpm::aruco::Renderer renderer(cpm::vehicle::World::load(kGates), cpm::aruco::Camera::load(kCamera));
    for (int i = 0; i < 5; ++i) {
        cpm::aruco::write_image((dir / ("frame_" + std::to_string(i) + ".png")).string(), renderer.render({1.0 + 0.1 * i, 0.1, 0.2}));
    }
    cpm::Participant participant(cpm_test::isolated_options());
    cpm::ReaderAbstract<ArucoMarkers> markers(participant, "arucoMarkers", {.keep_all = true});
    // The node's writer is best effort (as every sensor topic); a replay waits for its first
    // reader, and this one exists before the node starts. Whether this reader has also matched the
    // writer by the first frame is not in the node's hands: one frame may still be lost to that.
    Process node({built_program("aruco_node"), "--vehicle_id", "5", "--camera", kCamera, "--world", kGates, "--images", dir.string(), "--fps", "2"});
    std::vector<ArucoMarkers> got;
    EXPECT_EQ(node.wait(30s), 0) << node.errors();
    cpm_test::wait_until([&] {
        for (auto& m : markers.take()) got.push_back(m);
        return got.size() >= 4;
    }, 5s);
    auto stats = last_json_line(node.output());
    EXPECT_EQ(stats["frames"].get<int>(), 5) << node.output();
    EXPECT_GE(got.size(), 4u);
    for (const auto& m : got) EXPECT_GE(m.markers().size(), 2u);
    std::filesystem::remove_all(dir);
}

TEST(ArucoEndToEnd, AVideoFileIsReplayedFrameByFrame)
{
    // A recorded drive as a video (Motion-JPEG in AVI, which OpenCV writes and reads by itself).
    const auto dir = temp_dir("video");
    const auto video = (dir / "drive.avi").string();
    {
        cpm::aruco::Renderer renderer(cpm::vehicle::World::load(kGates), cpm::aruco::Camera::load(kCamera));
        cv::VideoWriter writer(video, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 5.0, cv::Size(640, 480), false);
        ASSERT_TRUE(writer.isOpened());
        for (int i = 0; i < 6; ++i) writer.write(renderer.render({1.0 + 0.1 * i, 0.1, 0.2}));
    }
    cpm::Participant participant(cpm_test::isolated_options());
    cpm::ReaderAbstract<ArucoMarkers> markers(participant, "arucoMarkers", {.keep_all = true});
    Process node({built_program("aruco_node"), "--vehicle_id", "5", "--camera", kCamera, "--world", kGates, "--video", video});
    EXPECT_EQ(node.wait(30s), 0) << node.errors();  // it ends with the video
    std::vector<ArucoMarkers> got;
    cpm_test::wait_until([&] {
        for (auto& m : markers.take()) got.push_back(m);
        return got.size() >= 5;
    }, 5s);
    auto stats = last_json_line(node.output());
    EXPECT_EQ(stats["frames"].get<int>(), 6) << node.output();
    EXPECT_EQ(stats["bad_frames"].get<int>(), 0);
    EXPECT_GE(got.size(), 5u);  // the first may go out before the writer matched (best effort)
    for (const auto& m : got) EXPECT_GE(m.markers().size(), 2u);  // the first gate, through JPEG
    std::filesystem::remove_all(dir);
}

TEST(ArucoEndToEnd, CalibrationFromRenderedCharucoPhotosFindsTheIntrinsics)
{
    const auto dir = temp_dir("calib");
    cpm::aruco::Camera truth = cpm::aruco::Camera::ideal(640, 480, 1.1);
    truth.camera_matrix(0, 2) = 331.0;  // the principal point off centre
    truth.camera_matrix(1, 2) = 232.5;
    const auto board = cpm::aruco::CharucoBoard::parse("charuco:5x7,0.04,0.03");
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> tilt(-0.5, 0.5), shift(-0.05, 0.05);
    for (int i = 0; i < 14; ++i) {
        // The board (0.2 × 0.28 m) 0.3..0.45 m ahead, tilted up to ±0.5 rad each way.
        const cv::Vec3d rvec(tilt(rng), tilt(rng), 0.2 * tilt(rng));
        const cv::Vec3d tvec(-0.1 + shift(rng), -0.14 + shift(rng), 0.3 + 0.01 * i);
        cpm::aruco::write_image((dir / ("view_" + std::to_string(i) + ".png")).string(),
                                cpm::aruco::render_board_view(board, truth, rvec, tvec));
    }
    const auto out = (dir / "camera.yaml").string();
    Process calibrate({built_program("cpm"), "camera", "calibrate", "--images", dir.string(), "--board", "charuco:5x7,0.04,0.03",
                       "--out", out});
    ASSERT_EQ(calibrate.wait(60s), 0) << calibrate.errors() << calibrate.output();
    EXPECT_NE(calibrate.output().find("reprojection error"), std::string::npos);
    const auto found = cpm::aruco::Camera::load(out);
    for (auto [row, col] : {std::pair{0, 0}, {1, 1}, {0, 2}, {1, 2}}) {
        EXPECT_NEAR(found.camera_matrix(row, col), truth.camera_matrix(row, col), 0.01 * truth.camera_matrix(row, col))
            << "K(" << row << "," << col << ")";
    }
    // A board with an even number of rows is refused, saying why.
    Process even({built_program("cpm"), "camera", "calibrate", "--images", dir.string(), "--board", "charuco:5x6,0.04,0.03", "--out", out});
    EXPECT_EQ(even.wait(20s), 2);
    EXPECT_NE(even.errors().find("use an odd number of rows"), std::string::npos) << even.errors();
    std::filesystem::remove_all(dir);
}

TEST(ArucoEndToEnd, IpsNodeNamesBadFramesAndMarkersAndGoesOn)
{
    // ips_node on the overhead frames of the test's own writer: a good frame (two cars), a frame
    // of the wrong size, then a frame where two cars wear one marker and a marker of no car lies
    // about: each named and counted, the cars it can tell apart still published.
    const std::string ceiling = cpm_test::source_dir() + "/scenarios/cameras/ceiling_1280x1024.yaml";
    const std::string floor = cpm_test::source_dir() + "/scenarios/maps/lab_floor.json";
    const auto camera = cpm::aruco::Camera::load(ceiling, cpm::aruco::CameraPlacement::overhead);
    const auto world = cpm::vehicle::World::load(floor);
    cpm::Participant participant(cpm_test::isolated_options());
    cpm::Writer<CameraFrame> frames(participant, "ipsCameraFrame");
    cpm::ReaderAbstract<VehicleObservation> seen(participant, "vehicleObservation", {.keep_all = true});
    Process node({built_program("ips_node"), "--camera", ceiling, "--world", floor});
    ASSERT_TRUE(frames.wait_for_matched(1, 20s)) << node.errors();
    ASSERT_TRUE(seen.wait_for_matched(1, 20s)) << node.errors();
    auto send = [&](const cv::Mat& image) {
        CameraFrame f;
        f.width(uint32_t(image.cols));
        f.height(uint32_t(image.rows));
        f.encoding("mono8");
        f.data(std::vector<uint8_t>(image.datastart, image.dataend));
        f.header().create_stamp().nanoseconds(cpm::get_time_ns());
        ASSERT_TRUE(frames.write(f));
    };
    cpm::aruco::OverheadRenderer lab(world, camera);
    cv::Mat good;
    lab.render({{3, {1.0, 1.0, 0.0}}, {4, {3.0, 2.0, 1.0}}}, good);
    std::vector<VehicleObservation> got;
    auto observed = [&](size_t n) {
        return cpm_test::wait_until([&] {
            for (auto& o : seen.take()) got.push_back(o);
            return got.size() >= n;
        }, 2s);
    };
    bool up = false;
    for (int i = 0; i < 20 && !up; ++i) {
        send(good);
        up = observed(2);
    }
    ASSERT_TRUE(up) << node.errors();
    EXPECT_NEAR(got[0].pose().x(), got[0].vehicle_id() == 3 ? 1.0 : 3.0, 0.01);
    send(cv::Mat(480, 640, CV_8UC1, cv::Scalar(95)));  // the wrong size
    std::this_thread::sleep_for(300ms);
    auto roofs = world.roof_markers();
    roofs[4].id = 3;                  // car 5 wears car 3's marker
    roofs.push_back({30, 30, 0.12, 0.12});  // marker 30: on no roof of the node's world
    cpm::vehicle::World wrong = world;
    wrong.set_overhead_markers(roofs, world.floor_markers());
    cpm::aruco::OverheadRenderer mixed(wrong, camera);
    cv::Mat confusing;
    mixed.render({{3, {1.0, 1.0, 0.0}}, {5, {2.0, 3.0, 0.0}}, {4, {3.0, 2.0, 1.0}}, {30, {3.6, 1.0, 0.0}}}, confusing);
    const size_t before = got.size();
    send(confusing);
    ASSERT_TRUE(observed(before + 1)) << node.errors();
    std::this_thread::sleep_for(300ms);
    for (auto& o : seen.take()) got.push_back(o);
    ASSERT_EQ(got.size(), before + 1) << "only car 4 can be told from the frame";
    EXPECT_EQ(got.back().vehicle_id(), 4);
    node.kill(SIGINT);
    ASSERT_EQ(node.wait(10s), 0) << node.errors();
    const auto stats = last_json_line(node.output());
    EXPECT_EQ(stats["bad_frames"].get<int>() + stats["dropped"].get<int>(), 1) << node.output();
    EXPECT_EQ(stats["seen_twice"], 1) << node.output();
    EXPECT_EQ(stats["unknown_markers"], 1) << node.output();
    const std::string errors = node.errors();
    if (stats["bad_frames"] == 1) {
        EXPECT_NE(errors.find("640×480 px, the camera file says 1280×1024"), std::string::npos) << errors;
    }
    EXPECT_NE(errors.find("roof marker 3 seen twice in one frame"), std::string::npos) << errors;
    EXPECT_NE(errors.find("marker 30 is on no car's roof and no floor marker"), std::string::npos) << errors;
    // Without a pose in the map, or without roof markers: named at the start.
    Process no_pose({built_program("ips_node"), "--camera", kCamera, "--world", floor});
    EXPECT_EQ(no_pose.wait(20s), 1);
    EXPECT_NE(no_pose.errors().find("sim_640x480.yaml: no overhead pose"), std::string::npos) << no_pose.errors();
    Process no_roofs({built_program("ips_node"), "--camera", ceiling, "--world", cpm_test::source_dir() + "/scenarios/maps/gates.json"});
    EXPECT_EQ(no_roofs.wait(20s), 1);
    EXPECT_NE(no_roofs.errors().find("gates.json: no roof_markers"), std::string::npos) << no_roofs.errors();
}

TEST(ArucoEndToEnd, CameraLocateFindsTheOverheadCameraThatMovedAndWritesItsPose)
{
    // A user's way: a frame of the ceiling camera where it hangs now (moved 6 cm and 5 cm down,
    // turned 1°, which the camera file does not know), drawn by cpm camera render --overhead;
    // cpm camera locate against the lab's file finds it and says how far it moved.
    const auto dir = temp_dir("locate");
    const std::string lab = cpm_test::source_dir() + "/scenarios/cameras/ceiling_1280x1024.yaml";
    const std::string floor = cpm_test::source_dir() + "/scenarios/maps/lab_floor.json";
    auto now = cpm::aruco::Camera::load(lab, cpm::aruco::CameraPlacement::overhead);
    cv::Matx33d turn;
    cv::Rodrigues(cv::Vec3d(0, 1, 0) * (1.0 * M_PI / 180), turn);
    now.overhead->rotation = turn * now.overhead->rotation;
    now.overhead->position += cv::Vec3d(0.06, 0, -0.05);
    const std::string moved = (dir / "moved.yaml").string(), image = (dir / "ceiling.png").string(), out = (dir / "located.yaml").string();
    now.save(moved);
    Process render({built_program("cpm"), "camera", "render", "--overhead", "--world", floor, "--camera", moved, "--cars", "1:1,1.2,0.3;2:3,2.5,2",
                    "--out", image});
    ASSERT_EQ(render.wait(30s), 0) << render.errors();
    EXPECT_NE(render.output().find("8 marker(s) drawn"), std::string::npos) << render.output();
    Process locate({built_program("cpm"), "camera", "locate", "--camera", lab, "--world", floor, "--image", image, "--out", out});
    ASSERT_EQ(locate.wait(30s), 0) << locate.errors();
    EXPECT_NE(locate.output().find("floor markers used: 40 41 42 43 44 45; other markers seen: 1 2"), std::string::npos) << locate.output();
    EXPECT_NE(locate.output().find("moved since it was last located: 78."), std::string::npos) << locate.output();
    const auto found = cpm::aruco::Camera::load(out, cpm::aruco::CameraPlacement::overhead);
    EXPECT_LT(cv::norm(found.overhead->position - now.overhead->position), 0.01);
    EXPECT_LT(cpm::aruco::rotation_angle(found.overhead->rotation, now.overhead->rotation) * 180 / M_PI, 0.2);
    EXPECT_LT(found.overhead->residual_px, 0.5);
    // A world whose floor is not this one, and a car's camera file: named, nothing written.
    std::filesystem::remove(out);
    Process other({built_program("cpm"), "camera", "locate", "--camera", lab, "--world", cpm_test::source_dir() + "/scenarios/maps/gates.json",
                   "--image", image, "--out", out});
    EXPECT_EQ(other.wait(30s), 1);
    EXPECT_NE(other.errors().find("gates.json: the world has 0 floor_markers"), std::string::npos) << other.errors();
    Process car({built_program("cpm"), "camera", "locate", "--camera", cpm_test::source_dir() + "/scenarios/cameras/sim_640x480.yaml",
                 "--world", floor, "--image", image, "--out", out});
    EXPECT_EQ(car.wait(30s), 1);
    EXPECT_NE(car.errors().find("ceiling.png: 1280×1024 px, but the camera file says 640×480"), std::string::npos) << car.errors();
    EXPECT_FALSE(std::filesystem::exists(out));
    std::filesystem::remove_all(dir);
}

namespace {

/// One drive of the gate machine on car 5 through `world` from `start`: the true path until
/// fsm_node stops in its final state. In real time, or on the lab's simulated clock (every
/// process with --simulated_time, stepped by `cpm lab clock --simulated`).
struct GateDrive
{
    std::vector<cpm::aruco::PathPoint> path;
    int fsm_exit = -1;
    std::string output;
    std::string states;  // each state the machine entered, with the car's pose then
};

enum class Clock
{
    real,
    simulated
};

GateDrive drive_gates(const std::string& world_file, const std::string& start, Clock clock)
{
    cpm::Participant participant(cpm_test::isolated_options());
    cpm::ReaderAbstract<VehicleObservation> observations(participant, "vehicleObservation", {.keep_all = true});
    std::vector<std::string> car_argv{built_program("cpm"), "vehicle", "sim", "--id", "5", "--map", world_file, "--camera", kCamera,
                                      "--start", start};
    std::vector<std::string> node_argv{built_program("aruco_node"), "--vehicle_id", "5", "--camera", kCamera, "--world", world_file};
    std::vector<std::string> fsm_argv{built_program("fsm_node"), "--vehicle_id", "5", "--fsm", kRoot + "/scenarios/fsm/gates.json"};
    const bool simulated = clock == Clock::simulated;
    if (simulated) {
        for (auto* argv : {&car_argv, &node_argv, &fsm_argv}) argv->push_back("--simulated_time");
    }
    Process car(car_argv);
    Process node(node_argv);
    Process fsm(fsm_argv);
    // Lab time for the course is at most two minutes, as the real-time drive's limit.
    std::optional<Process> lab_clock;
    if (simulated) {
        lab_clock.emplace(std::vector<std::string>{built_program("cpm"), "lab", "clock", "--nodes",
                                                   "firmware_sim_5,vehicle_bridge_5,camera_sim_5,aruco_node_5,fsm_node_5",
                                                   "--simulated", "--until", "120s"});
    }
    cpm::ReaderAbstract<FsmStatus> statuses(participant, "fsmStatus", {.keep_all = true});
    GateDrive run;
    int32_t state = -1;
    auto collect = [&] {
        for (auto& o : observations.take()) {
            run.path.push_back({o.header().create_stamp().nanoseconds() * 1e-9, {o.pose().x(), o.pose().y(), o.pose().yaw()}});
        }
        for (auto& s : statuses.take()) {
            if (s.state_id() == state) continue;
            state = s.state_id();
            char line[160];
            const auto& at = run.path.empty() ? cpm::aruco::PathPoint{} : run.path.back();
            std::snprintf(line, sizeof line, "  t %.2f s: state %d (%s), car at x %.3f y %.3f yaw %.3f\n",
                          at.t - (run.path.empty() ? 0 : run.path.front().t), state, s.state_type().c_str(), at.pose.x, at.pose.y,
                          at.pose.yaw);
            run.states += line;
        }
    };
    // On the lab clock the course ends in lab time (the machine stops, or the clock at 120 s of
    // lab time); the real-time limit there only guards against a hang (a course took up to 4
    // minutes under TSan beside other tests).
    bool machine_stopped = false;
    (void)cpm_test::wait_until([&] {
        collect();
        machine_stopped = fsm.wait(0ms) >= 0;
        return machine_stopped || (lab_clock && lab_clock->wait(0ms) >= 0);
    }, simulated ? 600s : 120s, 20ms);
    EXPECT_TRUE(machine_stopped) << "the machine did not reach its final state"
                                 << (simulated ? " within 120 s of lab time or 10 minutes\n" : " within 120 s\n")
                                 << "its states:\n" << run.states << fsm.output()
                                 << fsm.errors() << "\naruco_node: " << node.errors() << "\ncar: " << car.errors()
                                 << (lab_clock ? "\nclock: " + lab_clock->output() + lab_clock->errors() : std::string());
    collect();
    run.fsm_exit = fsm.wait(10s);
    run.output = fsm.output();
    if (lab_clock) {
        lab_clock->kill(SIGINT);
        lab_clock->wait(10s);
    }
    node.kill(SIGINT);
    node.wait(10s);
    car.kill(SIGINT);
    car.wait(10s);
    if (simulated) {
        // Each tick of the marker finder found the camera's frame of that moment, and each tick of
        // the car's controller and bridge the other's packet: nothing left to the machine's load.
        EXPECT_EQ(node.errors().find("no new camera frame"), std::string::npos) << node.errors();
        EXPECT_EQ(car.errors().find("the run will not repeat exactly"), std::string::npos) << car.errors();
    }
    return run;
}

/// What the test's own reader missed of the car's 50 Hz observations (best effort, like every
/// cpm topic): the gates are judged on this path, so a failure names it ("" when none).
std::string missed_observations(const std::vector<cpm::aruco::PathPoint>& path)
{
    size_t missed = 0;
    double widest = 0, at = 0;
    for (size_t i = 1; i < path.size(); ++i) {
        const double gap = path[i].t - path[i - 1].t;
        if (gap < 0.03) continue;
        missed += size_t(std::lround(gap / 0.02)) - 1;
        if (gap > widest) widest = gap, at = path[i - 1].t - path.front().t;
    }
    if (missed == 0) return "";
    char text[160];
    std::snprintf(text, sizeof text, "the test's reader missed %zu observations (widest gap %.0f ms, at t %.2f s)\n", missed,
                  widest * 1e3, at);
    return text;
}

/// Drives the gate machine through the seeded courses and judges every gate (crossed in order,
/// 5 cm from each marker's edge at least).
void drive_seeded_courses(const std::vector<uint32_t>& seeds, Clock clock)
{
    const cpm::vehicle::VehicleParameters params;
    const auto dir = temp_dir("gates");
    for (uint32_t seed : seeds) {
        const auto world = cpm::aruco::gate_course(seed);
        const auto file = (dir / ("course_" + std::to_string(seed) + ".json")).string();
        std::ofstream(file) << world.to_json();
        std::mt19937 rng(seed);
        const double heading = std::uniform_real_distribution<double>(-M_PI / 4, M_PI / 4)(rng);
        auto run = drive_gates(file, "0,0," + std::to_string(heading), clock);
        EXPECT_EQ(run.fsm_exit, 0) << run.output;
        auto passages = cpm::aruco::gate_passages(world, run.path, params.width);
        const std::string missed = missed_observations(run.path);
        std::string why;
        EXPECT_TRUE(cpm::aruco::all_gates_passed(passages, 0.05, &why)) << "seed " << seed << ": " << why << "\n" << missed << run.states << run.output;
        std::printf("seed %u, the machine's states:\n%s", seed, run.states.c_str());
        std::printf("seed %u: %zu observations; %s", seed, run.path.size(),
                    missed.empty() ? "none missed\n" : missed.c_str());
        for (const auto& p : passages) std::printf("seed %u gate %d: %.3f m from its centre\n", seed, p.gate + 1, p.offset);
    }
    std::filesystem::remove_all(dir);
}

}  // namespace

// In real time, as a lab drives: the camera, the marker finder and the machine each on their own
// clock, the frames' delay what this machine makes of it. One course; more on the lab clock below.
TEST(ArucoEndToEnd, FsmNodeDrivesThroughEveryGateOfASeededCourse)
{
#ifdef CPM_TEST_SANITIZED
    GTEST_SKIP() << "a sanitizer slows the camera pipeline 5-15x, more than a real-time loop judged to 5 cm allows; "
                    "the courses on the lab clock (below) run the same processes under it";
#endif
    drive_seeded_courses({11}, Clock::real);
}

// The same processes on the lab's simulated clock: each frame's markers reach the machine before
// the clock moves on, so the drive is the same however busy the machine (and may run beside
// other tests).
TEST(ArucoEndToEnd, FsmNodeDrivesThroughEveryGateOfSeededCoursesOnTheLabClock)
{
#ifdef CPM_TEST_SANITIZED
    // One course there: it takes 1.5 to 4 minutes at a sanitizer's pace and runs the same code.
    drive_seeded_courses({11}, Clock::simulated);
#else
    drive_seeded_courses({11, 12, 13}, Clock::simulated);
#endif
}

// A machine that looks for gates does not drive blind while its camera and marker finder come
// up (later than the car): it brakes, says what it waits for, and drives once markers come.
TEST(ArucoEndToEnd, AGateMachineStandsBrakedUntilItsCamerasFirstMarkersCome)
{
    cpm::Participant participant(cpm_test::isolated_options());
    cpm::ReaderAbstract<VehicleObservation> observations(participant, "vehicleObservation", {.keep_all = true});
    Process car({built_program("cpm"), "vehicle", "sim", "--id", "5", "--map", kGates, "--camera", kCamera, "--start", "1.0,0.1,0.2"});
    Process fsm({built_program("fsm_node"), "--vehicle_id", "5", "--fsm", kRoot + "/scenarios/fsm/gates.json"});
    ASSERT_TRUE(cpm_test::wait_until([&] {
        return fsm.errors().find("vehicle 5: no ArucoMarkers yet (the machine looks for markers); braking until fresh input arrives") !=
               std::string::npos;
    }, 20s)) << fsm.errors();
    std::this_thread::sleep_for(1s);
    auto moved = [&] {
        double most = 0;
        for (const auto& o : observations.take()) most = std::max(most, std::hypot(o.pose().x() - 1.0, o.pose().y() - 0.1));
        return most;
    };
    EXPECT_LT(moved(), 0.01) << "the car drove before the machine saw a marker\n" << fsm.errors();
    Process node({built_program("aruco_node"), "--vehicle_id", "5", "--camera", kCamera, "--world", kGates});
    double most = 0;
    EXPECT_TRUE(cpm_test::wait_until([&] { return (most = std::max(most, moved())) > 0.2; }, 20s))
        << "the car stood " << most << " m from its start\n" << fsm.errors() << node.errors();
    EXPECT_NE(fsm.errors().find("vehicle 5: input fresh again; running"), std::string::npos) << fsm.errors();
    for (auto* p : {&fsm, &node, &car}) {
        p->kill(SIGINT);
        p->wait(10s);
    }
}

// A marker finder told another rate than the camera's waits in vain on the ticks without a frame:
// it says so, naming the rate, and still takes every frame that comes.
TEST(ArucoEndToEnd, AMarkerFinderAtAnotherRateThanItsCameraSaysSoOnTheLabClock)
{
    Process car({built_program("cpm"), "vehicle", "sim", "--id", "5", "--map", kGates, "--camera", kCamera, "--camera-rate", "10",
                 "--start", "1.0,0.1,0.2", "--simulated_time"});
    Process node({built_program("aruco_node"), "--vehicle_id", "5", "--camera", kCamera, "--world", kGates, "--simulated_time"});
    Process clock({built_program("cpm"), "lab", "clock", "--nodes", "firmware_sim_5,vehicle_bridge_5,camera_sim_5,aruco_node_5",
                   "--simulated", "--until", "3s"});
    ASSERT_EQ(clock.wait(60s), 0) << clock.output() << clock.errors();
    // The clock's stop ends the timers: the node prints its counts and exits by itself.
    ASSERT_EQ(node.wait(10s), 0) << node.errors();
    EXPECT_NE(node.errors().find("no new camera frame at lab time"), std::string::npos) << node.errors();
    EXPECT_NE(node.errors().find("--rate 30 Hz"), std::string::npos) << node.errors();
    const auto stats = last_json_line(node.output());
    EXPECT_GE(stats.value("frames", 0), 25) << node.output();  // 10 Hz for 3 s of lab time
    EXPECT_LE(stats.value("frames", 0), 31) << node.output();
    car.kill(SIGINT);
    car.wait(10s);
}
