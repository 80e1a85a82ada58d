#pragma once
#include <cpm/CommandLine.hpp>
#include <cpm/aruco/Camera.hpp>
#include <cpm/aruco/Detector.hpp>

#include <string>
#include <vector>

namespace cpm::aruco {

/// The flags aruco_node and `cpm aruco detect` share: --camera FILE, --world FILE,
/// --marker-size M, --dictionary NAME, --no-subpixel, --aruco3.
std::vector<cli::FlagSpec> detector_flags();

/// The usage lines of those flags.
extern const char* const kDetectorFlagsHelp;

struct DetectorSetup
{
    Camera camera;
    DetectorOptions options;
    MarkerSizes sizes;
};

/// Reads the camera and world files and checks the values; throws cpm::cli::UsageError or
/// cpm::Error naming `command`, the flag, file or value.
DetectorSetup detector_setup(const cli::ParsedArgs& parsed, const std::string& command);

}  // namespace cpm::aruco
