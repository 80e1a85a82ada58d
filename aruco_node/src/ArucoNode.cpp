#include <cpm/aruco/ArucoNode.hpp>

#include "FrameSource.hpp"

#include <cpm/AsyncReader.hpp>
#include <cpm/Error.hpp>
#include <cpm/LogThrottle.hpp>
#include <cpm/Logging.hpp>
#include <cpm/Reader.hpp>
#include <cpm/Timer.hpp>
#include <cpm/timer_ids.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/init.hpp>
#include <cpm/percentile.hpp>
#include <cpm/topics.hpp>

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <deque>
#include <mutex>
#include <thread>

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
          writer(topics::aruco_markers.name, topics::aruco_markers.writer)
    {
        if (options.source != FrameSourceKind::topic && init_settings().simulated_time) {
            throw Error("aruco_node: --simulated_time takes frames from the cameraFrame topic only (camera_sim on the same clock); " +
                        options.path + " is read in real time");
        }
        switch (options.source) {
        case FrameSourceKind::device: source = open_device(options.path); break;
        case FrameSourceKind::video: source = open_video(options.path); break;
        case FrameSourceKind::images: source = open_images(options.path, options.fps); break;
        case FrameSourceKind::topic: break;
        }
    }

    /// One frame: detect, publish, count.
    void process(const cv::Mat& gray, uint64_t exposure_ns)
    {
        // Processing on the real clock (lab time stands still in a simulated tick); latency on the lab's.
        const auto start = std::chrono::steady_clock::now();
        // Counted aside and added under the lock afterwards: stats() never waits for a detection.
        ArucoNodeStats frame;
        const ArucoMarkers message = markers_message(detector, options.vehicle_id, gray, exposure_ns, &frame);
        (void)writer.write(message);
        const uint64_t done = get_time_ns();
        const auto took = std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - start).count();
        std::lock_guard<std::mutex> lock(mutex);
        counts.frames += frame.frames;
        counts.markers += frame.markers;
        counts.unknown_size += frame.unknown_size;
        processing_ns.push_back(uint64_t(took));
        latency_ns.push_back(done > exposure_ns ? done - exposure_ns : 0);
        if (processing_ns.size() > 100000) {  // bounded: keep the newest
            processing_ns.pop_front();
            latency_ns.pop_front();
        }
    }

    void bad_frame(const std::string& why)
    {
        std::lock_guard<std::mutex> lock(mutex);
        ++counts.bad_frames;
        uint64_t held = 0;
        if (bad_log.allow(get_time_ns(), held)) {
            CPM_LOG_WARN("aruco_node %u: frame skipped: %s (%llu more since the last report)", unsigned(options.vehicle_id), why.c_str(),
                         (unsigned long long)held);
        }
    }

    /// The topic source: the newest frame of the car in each batch; the others are dropped.
    void on_frames(std::vector<CameraFrame>& batch)
    {
        const CameraFrame* newest = nullptr;
        uint64_t mine = 0;
        for (const auto& f : batch) {
            if (f.vehicle_id() != options.vehicle_id) continue;
            ++mine;
            newest = &f;
        }
        if (!newest) return;
        {
            std::lock_guard<std::mutex> lock(mutex);
            counts.dropped += mine - 1;
        }
        process_frame(*newest);
    }

    void process_frame(const CameraFrame& f)
    {
        std::string why;
        cv::Mat gray = frame_image(f, options.camera, why);
        if (gray.empty()) {
            bad_frame(why);
            return;
        }
        process(gray, f.header().create_stamp().nanoseconds());
    }

    /// The topic source on the lab's simulated clock: one tick per camera frame, kSimulatedDetection_ns
    /// after the camera's. The camera wrote its frame before the clock moved on, but it may still
    /// be in flight: a tick with no new frame waits for one (up to 100 ms of real time, once the
    /// camera has sent a first frame).
    void run_simulated(const std::function<bool()>& stop_requested)
    {
        const auto period_ns = static_cast<uint64_t>(1e9 / options.frame_rate_hz);
        const uint64_t offset_ns = std::min(kSimulatedDetection_ns, period_ns / 2);
        Reader<CameraFrame> frames(topics::camera_frame.name, topics::camera_frame.reader_for(options.vehicle_id));
        uint64_t last_stamp = 0;
        bool seen_any = false;
        const std::string node_id = timer_ids::aruco_node(options.vehicle_id);
        if (!wait_for_inputs(node_id, {{topics::camera_frame.name, [&] { return frames.matched_publications(); }}}, stop_requested)) {
            return;
        }
        auto timer = Timer::create(node_id, period_ns, offset_ns,
                                   TimerOptions{.wait_for_start = false, .simulated_time_allowed = true});
        timer->run_until(stop_requested, [&](uint64_t t) {
            auto newest = frames.get_sample(t);
            auto fresh = [&] { return newest.valid && newest.sample.header().create_stamp().nanoseconds() > last_stamp; };
            const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(100);
            while (seen_any && !fresh() && !stop_requested()) {
                const auto left = deadline - std::chrono::steady_clock::now();
                if (left <= std::chrono::nanoseconds(0)) break;
                (void)frames.wait_for_new_sample(left);
                newest = frames.get_sample(t);
            }
            if (!fresh()) {
                uint64_t held = 0;
                if (seen_any && no_frame_log.allow(t, held)) {
                    CPM_LOG_WARN("aruco_node %u: no new camera frame at lab time %.3f s within 100 ms; is camera_sim on the "
                                 "simulated clock at --rate %g Hz? (%llu more since the last report)",
                                 unsigned(options.vehicle_id), double(t) * 1e-9, options.frame_rate_hz, (unsigned long long)held);
                }
                return;
            }
            seen_any = true;
            last_stamp = newest.sample.header().create_stamp().nanoseconds();
            process_frame(newest.sample);
        });
    }

    ArucoNodeOptions options;
    MarkerDetector detector;
    Writer<ArucoMarkers> writer;
    std::unique_ptr<FrameSource> source;
    mutable std::mutex mutex;
    ArucoNodeStats counts;
    LogThrottle bad_log;
    LogThrottle no_frame_log;  ///< simulated time: a tick whose frame never came
    std::deque<uint64_t> processing_ns, latency_ns;
};

ArucoNode::ArucoNode(ArucoNodeOptions options) : impl_(std::make_unique<Impl>(std::move(options))) {}

ArucoNode::~ArucoNode() = default;

void ArucoNode::run(const std::function<bool()>& stop_requested)
{
    Impl& d = *impl_;
    if (d.options.source == FrameSourceKind::topic && init_settings().simulated_time) {
        d.run_simulated(stop_requested);
        return;
    }
    if (d.options.source == FrameSourceKind::topic) {
        // Depth 8: frames that pile up while one is processed arrive in the next batch and are
        // counted as dropped (more than 8 in one processing time are dropped uncounted).
        ReaderOptions ro = topics::camera_frame.reader;
        ro.history_depth = 8;
        AsyncReader<CameraFrame> frames([&d](std::vector<CameraFrame>& batch) { d.on_frames(batch); }, topics::camera_frame.name, ro);
        while (!stop_requested()) std::this_thread::sleep_for(std::chrono::milliseconds(20));
        frames.stop();
        return;
    }
    // A replay has no clock to keep: it waits (up to 3 s) for its first reader, so that the
    // first frames do not go out to nobody (the topic is best effort, as every sensor's).
    if (d.options.source == FrameSourceKind::video || d.options.source == FrameSourceKind::images) {
        (void)d.writer.wait_for_matched(1, std::chrono::seconds(3));
    }
    while (!stop_requested()) {
        cv::Mat gray = d.source->next();
        if (gray.empty()) break;  // the end of a video or folder
        if (gray.type() != CV_8UC1) {
            d.bad_frame(d.source->current() + ": cannot read the image");
            continue;
        }
        if (const std::string why = d.options.camera.size_mismatch(gray.cols, gray.rows); !why.empty()) {
            d.bad_frame(d.source->current() + ": " + why);
            continue;
        }
        d.process(gray, get_time_ns());
    }
}

ArucoNodeStats ArucoNode::stats() const
{
    std::lock_guard<std::mutex> lock(impl_->mutex);
    return impl_->counts;
}

std::string ArucoNode::stats_json() const
{
    std::lock_guard<std::mutex> lock(impl_->mutex);
    const auto& c = impl_->counts;
    std::vector<uint64_t> proc(impl_->processing_ns.begin(), impl_->processing_ns.end());
    std::vector<uint64_t> lat(impl_->latency_ns.begin(), impl_->latency_ns.end());
    char line[512];
    std::snprintf(line, sizeof line,
                  "{\"vehicle_id\": %u, \"frames\": %llu, \"dropped\": %llu, \"bad_frames\": %llu, \"markers\": %llu, "
                  "\"unknown_size\": %llu, \"processing_ms_p50\": %.3f, \"latency_ms_p50\": %.3f, \"latency_ms_p99\": %.3f}",
                  unsigned(impl_->options.vehicle_id), (unsigned long long)c.frames, (unsigned long long)c.dropped,
                  (unsigned long long)c.bad_frames, (unsigned long long)c.markers, (unsigned long long)c.unknown_size,
                  percentile(proc, 0.5) * 1e-6, percentile(lat, 0.5) * 1e-6, percentile(lat, 0.99) * 1e-6);
    return line;
}

}  // namespace cpm::aruco
