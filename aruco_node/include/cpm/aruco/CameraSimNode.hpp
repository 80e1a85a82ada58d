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

}  // namespace cpm::aruco
