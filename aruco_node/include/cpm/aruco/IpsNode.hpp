#pragma once
#include <cpm/aruco/ArucoNode.hpp>
#include <cpm/aruco/Camera.hpp>
#include <cpm/aruco/Detector.hpp>
#include <cpm/aruco/Overhead.hpp>
#include <cpm/vehicle/World.hpp>

#include <VehicleObservation.h>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace cpm::aruco {

struct IpsNodeOptions
{
    Camera camera;          ///< with its overhead pose
    vehicle::World world;   ///< roof markers (which car wears which) and floor markers
    DetectorOptions detector;
    FrameSourceKind source = FrameSourceKind::topic;  ///< topic: ipsCameraFrame
    std::string path;       ///< device, video file or image folder
    double fps = 30;        ///< replay rate of an image folder
    /// Simulated time: the camera's rate; ips_node ticks (timer ips_node) once per frame, a
    /// detection's time after the camera.
    double frame_rate_hz = 50;
    /// A floor-marker residual above this says the camera moved since it was located.
    double moved_px = 2.0;
};

/// Counts since the start.
struct IpsNodeStats
{
    uint64_t frames = 0;          ///< frames processed
    uint64_t dropped = 0;         ///< arrived while another was processed, never looked at
    uint64_t bad_frames = 0;      ///< size or encoding disagreed with the camera file
    uint64_t observations = 0;    ///< VehicleObservations published
    uint64_t unknown_markers = 0; ///< markers on no roof and no floor (each id logged once)
    uint64_t seen_twice = 0;      ///< roof markers found twice in one frame (not published)
    uint64_t misfits = 0;         ///< roof markers whose size on the roof's plane is wrong (not published)
    uint64_t moved_frames = 0;    ///< frames whose floor markers say the camera moved
    double floor_residual_px = -1;///< the newest frame's floor-marker residual (-1: none seen)
};

/// The observations of one frame: one per car found, create_stamp = valid_after = exposure.
std::vector<VehicleObservation> observations_of(const OverheadView& view, uint64_t exposure_ns);

/// ips_node's work: overhead frames → every seen car's VehicleObservation (a car not seen is
/// not published: its readers age it out). Frames from the ipsCameraFrame topic (the overhead
/// camera_sim, or a camera node), a device, a video or an image folder; on the lab's simulated
/// clock one tick per frame, as aruco_node. Uses the process's default participant.
class IpsNode
{
public:
    /// Throws cpm::Error naming what is missing (the camera's pose, the world's roof markers) or
    /// the source it cannot open.
    explicit IpsNode(IpsNodeOptions options);
    ~IpsNode();
    IpsNode(const IpsNode&) = delete;
    IpsNode& operator=(const IpsNode&) = delete;

    void run(const std::function<bool()>& stop_requested);
    IpsNodeStats stats() const;
    /// One JSON line: the counts, processing_ms_p50/p99, latency_ms_p50/p99 (exposure → published).
    std::string stats_json() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace cpm::aruco
