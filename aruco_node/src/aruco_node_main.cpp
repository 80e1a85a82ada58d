// aruco_node: a car's camera frames → ArucoMarkers (pose in the car frame). The work is
// cpm::aruco::ArucoNode's.
#include <cpm/CommandLine.hpp>
#include <cpm/aruco/ArucoNode.hpp>
#include <cpm/aruco/DetectorFlags.hpp>
#include <cpm/init.hpp>

#include <cstdio>
#include <cstdlib>
#include <string>

namespace {

const std::string kHelp = std::string(
    "usage: aruco_node --vehicle_id N --camera FILE [--device /dev/videoN | --video FILE | --images DIR [--fps 30]]\n"
    "                  [--world FILE] [--marker-size M] [--dictionary NAME] [--no-subpixel] [--aruco3]\n"
    "                  [--simulated_time [--rate 30]] [--dds_domain N]\n"
    "\n"
    "Finds ArUco markers in car N's camera frames (OpenCV, sub-pixel corners), estimates each\n"
    "marker's pose (solvePnP, IPPE_SQUARE) and publishes ArucoMarkers for every frame (also when\n"
    "empty) with the frame's exposure time as create_stamp; poses are in the car frame (x forward,\n"
    "y left) through the camera's mounting. Frames that arrive while one is processed are\n"
    "dropped and counted. Frames come from the 'cameraFrame' topic (default: the synthetic\n"
    "camera, camera_sim), a V4L2 device, a video file or a folder of images (replayed in name\n"
    "order at --fps; a replay first waits up to 3 s for a reader of arucoMarkers, so that its first\n"
    "frames do not go out to nobody). On SIGINT/SIGTERM, or at the end of a video or folder, it prints one JSON\n"
    "line of statistics and exits 0.\n"
    "\n"
    "--simulated_time: frames from the cameraFrame topic on the lab's simulated clock (camera_sim\n"
    "--simulated_time, cpm vehicle sim --simulated_time --camera): one tick per frame (timer\n"
    "aruco_node_N, to name to cpm lab clock --simulated --nodes), 5 ms of lab time after the\n"
    "camera's, each waiting for that frame; --rate is the camera's rate in Hz (default 30).\n"
    "\n") + cpm::aruco::kDetectorFlagsHelp;

int run(int argc, char** argv)
{
    auto flags = cpm::aruco::detector_flags();
    flags.insert(flags.end(), {{"--vehicle_id", true}, {"--device", true}, {"--video", true}, {"--images", true}, {"--fps", true}, {"--rate", true}});
    auto parsed = cpm::cli::parse_flags(argc, argv, flags, "aruco_node");
    if (!parsed.has("--vehicle_id")) throw cpm::cli::UsageError("aruco_node: --vehicle_id is required");
    int sources = int(parsed.has("--device")) + int(parsed.has("--video")) + int(parsed.has("--images"));
    if (sources > 1) throw cpm::cli::UsageError("aruco_node: give one of --device, --video, --images");
    const bool simulated = cpm::parse_init_settings(argc, argv, std::getenv("CPM_DOMAIN_ID")).simulated_time;
    if (simulated && sources > 0) {
        throw cpm::cli::UsageError(std::string("aruco_node: --simulated_time takes frames from the cameraFrame topic only; ") +
                                   (parsed.has("--device") ? "--device" : parsed.has("--video") ? "--video" : "--images") +
                                   " is read in real time");
    }
    if (parsed.has("--rate") && !simulated) {
        throw cpm::cli::UsageError("aruco_node: --rate is the camera's rate on the simulated clock; it needs --simulated_time "
                                   "(in real time each frame is taken as it arrives)");
    }
    auto setup = cpm::aruco::detector_setup(parsed, "aruco_node");
    cpm::aruco::ArucoNodeOptions o;
    o.vehicle_id = static_cast<uint8_t>(cpm::cli::parse_integer("--vehicle_id", parsed.get("--vehicle_id"), 1, 255));
    o.camera = setup.camera;
    o.detector = setup.options;
    o.sizes = setup.sizes;
    o.fps = cpm::cli::parse_number("--fps", parsed.get("--fps", "30"), 0.1, 1000);
    o.frame_rate_hz = cpm::cli::parse_number("--rate", parsed.get("--rate", "30"), 0.1, 1000);
    for (auto [flag, kind] : {std::pair{"--device", cpm::aruco::FrameSourceKind::device},
                              {"--video", cpm::aruco::FrameSourceKind::video},
                              {"--images", cpm::aruco::FrameSourceKind::images}}) {
        if (parsed.has(flag)) {
            o.source = kind;
            o.path = parsed.get(flag);
        }
    }
    cpm::init(argc, argv);
    cpm::aruco::ArucoNode node(std::move(o));
    return cpm::cli::run_node(node);
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "aruco_node", kHelp.c_str(), run); }
