#pragma once
// What aruco_node and ips_node share: taking camera frames from one source (the topic, a device,
// a video, an image folder; on the lab's simulated clock one tick per frame) and handing each
// usable one to the node's work, with bad frames counted and logged at most once a second.
#include <cpm/ReaderOptions.hpp>
#include <cpm/aruco/ArucoNode.hpp>
#include <cpm/aruco/Camera.hpp>

#include <CameraFrame.h>

#include <opencv2/core.hpp>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

namespace cpm::aruco {

struct FrameLoopOptions
{
    std::string who;          ///< the node in messages ("aruco_node 3", "ips_node")
    std::string timer_id;     ///< its timer on the simulated clock
    const char* topic = "";   ///< the frames' topic
    ReaderOptions reader;     ///< for the topic (the camera's key)
    uint8_t vehicle_id = 0;   ///< the frames taken from the topic: this key's
    Camera camera;
    FrameSourceKind source = FrameSourceKind::topic;
    std::string path;
    double fps = 30;
    double frame_rate_hz = 30;
};

/// How long the node's work took per frame (real time) and how long after its exposure each
/// frame's result was out (the lab's clock), over the newest 100000 frames.
struct FrameTimes
{
    double processing_ms_p50 = 0, processing_ms_p99 = 0, latency_ms_p50 = 0, latency_ms_p99 = 0;
};

class FrameLoop
{
public:
    /// `process(gray, exposure_ns)`: one usable frame. Opens the source; throws cpm::Error naming
    /// the device, file or folder when it cannot, or a file source under --simulated_time.
    FrameLoop(FrameLoopOptions options, std::function<void(const cv::Mat&, uint64_t)> process);
    ~FrameLoop();

    /// Until `stop_requested()` (or a video / image folder ends). `before_replay` runs before a
    /// video or folder's first frame.
    void run(const std::function<bool()>& stop_requested, const std::function<void()>& before_replay);

    uint64_t dropped() const;
    uint64_t bad_frames() const;
    FrameTimes times() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace cpm::aruco
