#pragma once
#include <cpm/aruco/Camera.hpp>
#include <cpm/aruco/Detector.hpp>

#include <ArucoMarkers.h>
#include <CameraFrame.h>

#include <opencv2/core.hpp>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

namespace cpm::aruco {

/// Where aruco_node's frames come from.
enum class FrameSourceKind
{
    topic,   ///< CameraFrame samples of the car (the synthetic camera, or a camera node)
    device,  ///< a V4L2 device, /dev/videoN
    video,   ///< a video file, replayed at its frame rate
    images,  ///< a folder of images, replayed in name order at `fps`
};

struct ArucoNodeOptions
{
    uint8_t vehicle_id = 0;
    Camera camera;
    DetectorOptions detector;
    MarkerSizes sizes;
    FrameSourceKind source = FrameSourceKind::topic;
    std::string path;   ///< device, video file or image folder
    double fps = 30;    ///< replay rate of an image folder
    /// Simulated time (--simulated_time; the topic source only): the camera's frame rate. The
    /// node then ticks on the lab clock (timer aruco_node_N) once per frame, a detection's time
    /// (kSimulatedDetection_ns, less for rates above 100 Hz) after the camera, and processes that
    /// frame; runs are repeatable.
    double frame_rate_hz = 30;
};

/// Simulated time: how long after the camera's tick aruco_node's tick comes, i.e. the lab time
/// a detection takes (about what one 640×480 frame takes on a lab computer).
inline constexpr uint64_t kSimulatedDetection_ns = 5'000'000;

/// Counts since the start.
struct ArucoNodeStats
{
    uint64_t frames = 0;          ///< frames processed (each gave one ArucoMarkers)
    uint64_t dropped = 0;         ///< arrived while another was processed, never looked at
    uint64_t bad_frames = 0;      ///< size or encoding disagreed with the camera file
    uint64_t markers = 0;         ///< markers published
    uint64_t unknown_size = 0;    ///< markers seen whose size is unknown (not published)
};

/// Turns one frame into the car's ArucoMarkers: detection, pose, car frame.
/// `create_stamp` of the result is `exposure_ns`.
ArucoMarkers markers_message(const MarkerDetector& detector, uint8_t vehicle_id, const cv::Mat& gray, uint64_t exposure_ns,
                             ArucoNodeStats* stats = nullptr);

/// The image of a CameraFrame (a view of its bytes, or converted to grey), checked against the
/// camera's size; an empty Mat and `why` when the frame is unusable.
cv::Mat frame_image(const CameraFrame& frame, const Camera& camera, std::string& why);

/// aruco_node's work: frames from one source → ArucoMarkers of the car, one per frame (also
/// when empty). Frames that arrive while one is processed are dropped and counted, never
/// queued. Under --simulated_time (topic source only) it ticks on the lab clock instead: each
/// tick takes the camera's newest frame (waiting up to 100 ms of real time for one not yet
/// arrived), so that the clock never runs ahead of the detection. Bad frames are counted and logged at most once a second. Uses the process's
/// default participant (cpm::init first).
class ArucoNode
{
public:
    /// Opens the source; throws cpm::Error naming the device, file or folder when it cannot.
    explicit ArucoNode(ArucoNodeOptions options);
    ~ArucoNode();
    ArucoNode(const ArucoNode&) = delete;
    ArucoNode& operator=(const ArucoNode&) = delete;

    /// Runs until `stop_requested()` (or a video / image folder ends).
    void run(const std::function<bool()>& stop_requested);
    ArucoNodeStats stats() const;
    /// {"vehicle_id": …, "frames": …, "dropped": …, "bad_frames": …, "markers": …, "unknown_size": …,
    ///  "processing_ms_p50": …, "latency_ms_p50": …, "latency_ms_p99": …}
    std::string stats_json() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace cpm::aruco
