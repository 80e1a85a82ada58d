#include <cpm/aruco/ArucoNode.hpp>

#include "FrameLoop.hpp"

#include <cpm/Logging.hpp>
#include <cpm/timer_ids.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/topics.hpp>

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <mutex>

namespace cpm::aruco {

ArucoMarkers markers_message(const MarkerDetector& detector, uint8_t vehicle_id, const cv::Mat& gray, uint64_t exposure_ns,
                             ArucoNodeStats* stats)
{
    ArucoMarkers out;
    out.vehicle_id(vehicle_id);
    out.header().create_stamp().nanoseconds(exposure_ns);
    out.header().valid_after_stamp().nanoseconds(exposure_ns);
    for (const auto& m : detector.observe(gray)) {
        if (!m.has_pose) {
            if (stats) ++stats->unknown_size;
            continue;
        }
        ArucoMarker a;
        a.id(m.id);
        for (int k = 0; k < 4; ++k) {
            a.corners()[k].x(m.corners[k].x);
            a.corners()[k].y(m.corners[k].y);
        }
        a.pose().x(m.x);
        a.pose().y(m.y);
        a.pose().yaw(m.yaw);
        a.distance(m.distance);
        out.markers().push_back(a);
    }
    if (stats) {
        ++stats->frames;
        stats->markers += out.markers().size();
    }
    return out;
}

cv::Mat frame_image(const CameraFrame& frame, const Camera& camera, std::string& why)
{
    const std::string& enc = frame.encoding();
    const size_t channels = enc == "mono8" ? 1 : enc == "bgr8" ? 3 : 0;
    if (channels == 0) {
        why = "encoding '" + enc + "' (known: mono8, bgr8)";
        return {};
    }
    why = camera.size_mismatch(int(frame.width()), int(frame.height()));
    if (!why.empty()) return {};
    if (frame.data().size() != size_t(frame.width()) * frame.height() * channels) {
        why = std::to_string(frame.data().size()) + " bytes of data for " + std::to_string(frame.width()) + "×" +
              std::to_string(frame.height()) + " " + enc;
        return {};
    }
    cv::Mat view(int(frame.height()), int(frame.width()), channels == 1 ? CV_8UC1 : CV_8UC3,
                 const_cast<uint8_t*>(frame.data().data()));
    if (channels == 1) return view;
    cv::Mat grey;
    cv::cvtColor(view, grey, cv::COLOR_BGR2GRAY);
    return grey;
}

struct ArucoNode::Impl
{
    explicit Impl(ArucoNodeOptions o)
        : options(std::move(o)), detector(options.camera, options.detector, options.sizes),
          writer(topics::aruco_markers.name, topics::aruco_markers.writer),
          loop(FrameLoopOptions{.who = "aruco_node " + std::to_string(options.vehicle_id),
                                .timer_id = timer_ids::aruco_node(options.vehicle_id),
                                .topic = topics::camera_frame.name,
                                .reader = topics::camera_frame.reader_for(options.vehicle_id),
                                .vehicle_id = options.vehicle_id,
                                .camera = options.camera,
                                .source = options.source,
                                .path = options.path,
                                .fps = options.fps,
                                .frame_rate_hz = options.frame_rate_hz},
               [this](const cv::Mat& gray, uint64_t exposure_ns) { process(gray, exposure_ns); })
    {
    }

    /// One frame: detect, publish, count.
    void process(const cv::Mat& gray, uint64_t exposure_ns)
    {
        // Counted aside and added under the lock afterwards: stats() never waits for a detection.
        ArucoNodeStats frame;
        const ArucoMarkers message = markers_message(detector, options.vehicle_id, gray, exposure_ns, &frame);
        (void)writer.write(message);
        std::lock_guard<std::mutex> lock(mutex);
        counts.frames += frame.frames;
        counts.markers += frame.markers;
        counts.unknown_size += frame.unknown_size;
    }

    ArucoNodeOptions options;
    MarkerDetector detector;
    Writer<ArucoMarkers> writer;
    mutable std::mutex mutex;
    ArucoNodeStats counts;
    FrameLoop loop;  ///< last: its thread calls process()
};

ArucoNode::ArucoNode(ArucoNodeOptions options) : impl_(std::make_unique<Impl>(std::move(options))) {}

ArucoNode::~ArucoNode() = default;

void ArucoNode::run(const std::function<bool()>& stop_requested)
{
    Impl& d = *impl_;
    // A replay has no clock to keep: it waits (up to 3 s) for its first reader, so that the
    // first frames do not go out to nobody (the topic is best effort, as every sensor's).
    d.loop.run(stop_requested, [&d] { (void)d.writer.wait_for_matched(1, std::chrono::seconds(3)); });
}

ArucoNodeStats ArucoNode::stats() const
{
    ArucoNodeStats c;
    {
        std::lock_guard<std::mutex> lock(impl_->mutex);
        c = impl_->counts;
    }
    c.dropped = impl_->loop.dropped();
    c.bad_frames = impl_->loop.bad_frames();
    return c;
}

std::string ArucoNode::stats_json() const
{
    const ArucoNodeStats c = stats();
    const FrameTimes t = impl_->loop.times();
    char line[512];
    std::snprintf(line, sizeof line,
                  "{\"vehicle_id\": %u, \"frames\": %llu, \"dropped\": %llu, \"bad_frames\": %llu, \"markers\": %llu, "
                  "\"unknown_size\": %llu, \"processing_ms_p50\": %.3f, \"latency_ms_p50\": %.3f, \"latency_ms_p99\": %.3f}",
                  unsigned(impl_->options.vehicle_id), (unsigned long long)c.frames, (unsigned long long)c.dropped,
                  (unsigned long long)c.bad_frames, (unsigned long long)c.markers, (unsigned long long)c.unknown_size,
                  t.processing_ms_p50, t.latency_ms_p50, t.latency_ms_p99);
    return line;
}

}  // namespace cpm::aruco
