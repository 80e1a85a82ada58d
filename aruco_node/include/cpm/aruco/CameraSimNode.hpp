#pragma once
#include <cpm/aruco/Camera.hpp>
#include <cpm/aruco/Renderer.hpp>
#include <cpm/vehicle/World.hpp>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

namespace cpm::aruco {

struct CameraSimOptions
{
    uint8_t vehicle_id = 0;
    Camera camera;
    vehicle::World world;
    RenderOptions render;
    double rate_hz = 30;
    /// Where the cars' true poses come from: vehicleObservation, or vehicleObservationTruth when
    /// the lab's positioning system writes vehicleObservation.
    std::string truth_topic = "vehicleObservation";
};

/// camera_sim's work: at rate_hz, renders what the car's camera sees from its true pose
/// (VehicleObservation, moved on to the moment of the frame by the car's motion between its
/// last two observations) and publishes it as a mono8 CameraFrame whose create_stamp is that
/// moment, the exposure. Under --simulated_time it ticks on the lab's simulated clock (timer
/// camera_sim_N) and the moment is lab time. Uses the process's default participant (cpm::init first).
class CameraSimNode
{
public:
    /// Throws cpm::Error naming a marker the dictionary does not have.
    explicit CameraSimNode(CameraSimOptions options);
    ~CameraSimNode();
    CameraSimNode(const CameraSimNode&) = delete;
    CameraSimNode& operator=(const CameraSimNode&) = delete;

    void run(const std::function<bool()>& stop_requested);
    /// {"vehicle_id": …, "frames": …, "without_pose": …, "render_ms_p50": …}
    std::string stats_json() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

/// camera_sim --overhead: the lab's positioning camera under the ceiling. At rate_hz it draws
/// every car of the world's roof_markers at its true pose (moved on to the frame's moment, as
/// the car's camera does) and publishes a mono8 CameraFrame (vehicle_id 0) on ipsCameraFrame.
/// Under --simulated_time it ticks on the lab clock (timer ips_camera).
class OverheadCameraSimNode
{
public:
    /// `options.camera` must have its overhead pose; `vehicle_id` is unused. Throws cpm::Error
    /// naming what is missing.
    explicit OverheadCameraSimNode(CameraSimOptions options);
    ~OverheadCameraSimNode();
    OverheadCameraSimNode(const OverheadCameraSimNode&) = delete;
    OverheadCameraSimNode& operator=(const OverheadCameraSimNode&) = delete;

    void run(const std::function<bool()>& stop_requested);
    /// {"frames": …, "cars_drawn": …, "render_ms_p50": …}
    std::string stats_json() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace cpm::aruco
