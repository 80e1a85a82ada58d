// camera_sim: the synthetic camera of a simulated car. The work is cpm::aruco::CameraSimNode's.
#include <cpm/CommandLine.hpp>
#include <cpm/aruco/CameraSimNode.hpp>
#include <cpm/init.hpp>

#include <cstdio>
#include <string>

namespace {

const char* kHelp =
    "usage: camera_sim --vehicle_id N --camera FILE --map FILE [--rate 30] [--noise SIGMA] [--blur K]\n"
    "                  [--seed S] [--dictionary NAME] [--truth_topic NAME] [--simulated_time] [--dds_domain N]\n"
    "       camera_sim --overhead --camera FILE --map FILE [--rate 50] [...]\n"
    "\n"
    "Renders what car N's camera sees from the car's true pose (VehicleObservation) in the map:\n"
    "each marker with its white quiet zone, projected through the camera model; markers behind\n"
    "the camera, facing away or hidden by a wall are left out. Publishes mono8 CameraFrame at\n"
    "--rate Hz with the pose's time as create_stamp. With --simulated_time it ticks on the lab's\n"
    "simulated clock (timer camera_sim_N, to name to cpm lab clock --simulated --nodes).\n"
    "\n"
    "--overhead: the lab's positioning camera under the ceiling instead. The camera file holds its\n"
    "pose in the map (world_x, world_y, world_z, world_rotation; cpm camera locate writes them),\n"
    "the map its roof_markers (which marker is on which car) and floor_markers. It draws the\n"
    "floor markers and every car of roof_markers (its body, its roof marker) at its true pose,\n"
    "through the lens's distortion, and publishes the frames on ipsCameraFrame (vehicle_id 0) at\n"
    "--rate Hz (default 50); on the simulated clock its timer is ips_camera. ips_node reads them.\n"
    "\n"
    "  --truth_topic NAME  where the cars' true poses are (default vehicleObservation; with\n"
    "                 --overhead vehicleObservationTruth, where simulators write them in a lab\n"
    "                 whose positioning system writes vehicleObservation)\n"
    "  --noise SIGMA  Gaussian noise, grey levels of 255 (default 0)\n"
    "  --blur K       K×K box blur (default none)\n"
    "  --seed S       noise seed (default: the vehicle id)\n"
    "On SIGINT/SIGTERM it prints one JSON line of statistics and exits 0.\n";

int run(int argc, char** argv)
{
    auto parsed = cpm::cli::parse_flags(argc, argv,
                                       {{"--vehicle_id", true}, {"--camera", true}, {"--map", true}, {"--rate", true},
                                        {"--noise", true}, {"--blur", true}, {"--seed", true}, {"--dictionary", true},
                                        {"--overhead", false}, {"--truth_topic", true}},
                                       "camera_sim");
    const bool overhead = parsed.has("--overhead");
    if (overhead && parsed.has("--vehicle_id")) {
        throw cpm::cli::UsageError("camera_sim: --overhead sees every car of the map's roof_markers; leave out --vehicle_id");
    }
    if (!overhead && !parsed.has("--vehicle_id")) throw cpm::cli::UsageError("camera_sim: --vehicle_id is required (or --overhead)");
    if (!parsed.has("--camera")) throw cpm::cli::UsageError("camera_sim: --camera FILE is required");
    if (!parsed.has("--map")) throw cpm::cli::UsageError("camera_sim: --map FILE is required (the world with its markers)");
    cpm::aruco::CameraSimOptions o;
    if (!overhead) o.vehicle_id = static_cast<uint8_t>(cpm::cli::parse_integer("--vehicle_id", parsed.get("--vehicle_id"), 1, 255));
    o.camera = cpm::aruco::Camera::load(parsed.get("--camera"),
                                        overhead ? cpm::aruco::CameraPlacement::overhead : cpm::aruco::CameraPlacement::on_car);
    o.world = cpm::vehicle::World::load(parsed.get("--map"));
    o.rate_hz = cpm::cli::parse_number("--rate", parsed.get("--rate", overhead ? "50" : "30"), 0.1, 1000);
    o.truth_topic = parsed.get("--truth_topic", overhead ? "vehicleObservationTruth" : "vehicleObservation");
    o.render.noise_sigma = cpm::cli::parse_number("--noise", parsed.get("--noise", "0"), 0, 128);
    o.render.blur = int(cpm::cli::parse_integer("--blur", parsed.get("--blur", "0"), 0, 31));
    o.render.seed = uint32_t(cpm::cli::parse_integer("--seed", parsed.get("--seed", std::to_string(o.vehicle_id)), 0, UINT32_MAX));
    o.render.dictionary = parsed.get("--dictionary", "DICT_4X4_50");
    cpm::init(argc, argv);
    if (overhead) {
        cpm::aruco::OverheadCameraSimNode node(std::move(o));
        return cpm::cli::run_node(node);
    }
    cpm::aruco::CameraSimNode node(std::move(o));
    return cpm::cli::run_node(node);
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "camera_sim", kHelp, run); }
