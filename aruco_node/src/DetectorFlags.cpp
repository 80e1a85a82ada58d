#include <cpm/aruco/DetectorFlags.hpp>

#include "ArucoCompat.hpp"

#include <cpm/vehicle/World.hpp>

namespace cpm::aruco {

std::vector<cli::FlagSpec> detector_flags()
{
    return {{"--camera", true}, {"--world", true}, {"--marker-size", true}, {"--dictionary", true}, {"--no-subpixel", false},
            {"--aruco3", false}};
}

const char* const kDetectorFlagsHelp =
    "  --camera FILE       camera file (OpenCV YAML: image size, camera_matrix, distortion_coefficients,\n"
    "                      mount_x/y/z/yaw/pitch on the car); required\n"
    "  --world FILE        map whose markers give each id's size (markers[].size)\n"
    "  --marker-size M     side of the black square, m, for ids the world does not list\n"
    "                      (without either, markers are found but have no pose)\n"
    "  --dictionary NAME   OpenCV dictionary (default DICT_4X4_50)\n"
    "  --no-subpixel       no sub-pixel corner refinement (on by default)\n"
    "  --aruco3            OpenCV's multi-scale ArUco3 search\n";

DetectorSetup detector_setup(const cli::ParsedArgs& parsed, const std::string& command)
{
    if (!parsed.has("--camera")) throw cli::UsageError(command + ": --camera FILE is required (the camera file)");
    DetectorSetup s;
    s.camera = Camera::load(parsed.get("--camera"));
    s.options.dictionary = parsed.get("--dictionary", "DICT_4X4_50");
    try {
        compat::dictionary(s.options.dictionary);
    } catch (const Error& e) {
        throw cli::UsageError(command + ": --dictionary: " + e.what());
    }
    s.options.subpixel = !parsed.has("--no-subpixel");
    s.options.aruco3 = parsed.has("--aruco3");
    const double fallback = parsed.has("--marker-size") ? cli::parse_number("--marker-size", parsed.get("--marker-size"), 0.001, 10) : 0;
    if (parsed.has("--world")) {
        s.sizes = MarkerSizes::from_world(vehicle::World::load(parsed.get("--world")), fallback);
    } else {
        s.sizes.fallback = fallback;
    }
    return s;
}

}  // namespace cpm::aruco
