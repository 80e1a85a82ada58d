// ips_node: the lab's positioning system. Overhead camera frames → every seen car's
// VehicleObservation. The work is cpm::aruco::IpsNode's.
#include <cpm/CommandLine.hpp>
#include <cpm/Error.hpp>
#include <cpm/aruco/IpsNode.hpp>
#include <cpm/init.hpp>

#include <cstdlib>
#include <string>

namespace {

const char* kHelp =
    "usage: ips_node --camera FILE --world FILE [--source dds|video:FILE|device:/dev/videoN|files:DIR]\n"
    "                [--rate HZ] [--fps 30] [--moved_px 2] [--dictionary NAME] [--simulated_time] [--dds_domain N]\n"
    "\n"
    "The lab's positioning system (IPS). Finds the marker on each car's roof in the overhead\n"
    "camera's frames and publishes the car's VehicleObservation: its pose in the map (the roof\n"
    "marker's centre and x axis), create_stamp = the frame's exposure. A car not seen is not\n"
    "published (its readers age it out). A marker on no roof and no floor is counted and logged once;\n"
    "a roof marker seen twice in one frame is not published, counted and logged.\n"
    "\n"
    "  --camera FILE   the overhead camera: lens and its pose in the map (world_x, world_y, world_z,\n"
    "                  world_rotation; cpm camera locate writes them)\n"
    "  --world FILE    a map with roof_markers {\"<vehicle id>\": {\"id\", \"size\", \"z\"}} and\n"
    "                  floor_markers [{\"id\", \"x\", \"y\", \"yaw\", \"size\"}]\n"
    "  --source        dds (default: the ipsCameraFrame topic, e.g. camera_sim --overhead), a video\n"
    "                  file, a V4L2 device, or a folder of images replayed at --fps in name order\n"
    "  --rate HZ       --simulated_time: the camera's rate (default 50); one tick (timer ips_node) per\n"
    "                  frame, 5 ms of lab time after the camera's\n"
    "  --moved_px PX   floor markers this far (RMS) from where the camera file puts them: the camera\n"
    "                  moved; logged once a second and counted (default 2)\n"
    "On SIGINT/SIGTERM, or at the end of a video or folder, it prints one JSON line of statistics\n"
    "and exits 0.\n";

int run(int argc, char** argv)
{
    auto parsed = cpm::cli::parse_flags(argc, argv,
                                       {{"--camera", true}, {"--world", true}, {"--source", true}, {"--rate", true}, {"--fps", true},
                                        {"--moved_px", true}, {"--dictionary", true}},
                                       "ips_node");
    if (!parsed.has("--camera")) throw cpm::cli::UsageError("ips_node: --camera FILE is required (the overhead camera)");
    if (!parsed.has("--world")) throw cpm::cli::UsageError("ips_node: --world FILE is required (the roof and floor markers)");
    cpm::aruco::IpsNodeOptions o;
    const std::string source = parsed.get("--source", "dds");
    auto after = [&](const std::string& prefix) { return source.substr(prefix.size()); };
    if (source == "dds") {
        o.source = cpm::aruco::FrameSourceKind::topic;
    } else if (source.rfind("video:", 0) == 0 && source.size() > 6) {
        o.source = cpm::aruco::FrameSourceKind::video;
        o.path = after("video:");
    } else if (source.rfind("device:", 0) == 0 && source.size() > 7) {
        o.source = cpm::aruco::FrameSourceKind::device;
        o.path = after("device:");
    } else if (source.rfind("files:", 0) == 0 && source.size() > 6) {
        o.source = cpm::aruco::FrameSourceKind::images;
        o.path = after("files:");
    } else {
        throw cpm::cli::UsageError("ips_node: --source '" + source + "': expected dds, video:FILE, device:/dev/videoN or files:DIR");
    }
    const bool simulated = cpm::parse_init_settings(argc, argv, std::getenv("CPM_DOMAIN_ID")).simulated_time;
    if (simulated && o.source != cpm::aruco::FrameSourceKind::topic) {
        throw cpm::cli::UsageError("ips_node: --simulated_time takes frames from the ipsCameraFrame topic only (--source dds); " + source +
                                   " is read in real time");
    }
    if (parsed.has("--rate") && !simulated) {
        throw cpm::cli::UsageError("ips_node: --rate is the camera's rate on the simulated clock; it needs --simulated_time");
    }
    o.camera = cpm::aruco::Camera::load(parsed.get("--camera"), cpm::aruco::CameraPlacement::overhead);
    o.world = cpm::vehicle::World::load(parsed.get("--world"));
    if (o.world.roof_markers().empty()) {
        throw cpm::Error(parsed.get("--world") + ": no roof_markers (which marker is on which car): {\"roof_markers\": {\"1\": {\"id\": 1}}}");
    }
    o.detector.dictionary = parsed.get("--dictionary", "DICT_4X4_50");
    o.frame_rate_hz = cpm::cli::parse_number("--rate", parsed.get("--rate", "50"), 0.1, 1000);
    o.fps = cpm::cli::parse_number("--fps", parsed.get("--fps", "30"), 0.1, 1000);
    o.moved_px = cpm::cli::parse_number("--moved_px", parsed.get("--moved_px", "2"), 0.01, 1000);
    cpm::init(argc, argv);
    cpm::aruco::IpsNode node(std::move(o));
    return cpm::cli::run_node(node);
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "ips_node", kHelp, run); }
