#include "FrameLoop.hpp"

#include "FrameSource.hpp"

#include <cpm/AsyncReader.hpp>
#include <cpm/Error.hpp>
#include <cpm/LogThrottle.hpp>
#include <cpm/Logging.hpp>
#include <cpm/Reader.hpp>
#include <cpm/Timer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/timer_ids.hpp>
#include <cpm/init.hpp>
#include <cpm/percentile.hpp>

#include <algorithm>
#include <chrono>
#include <deque>
#include <mutex>
#include <optional>
#include <thread>

namespace cpm::aruco {

struct FrameLoop::Impl
{
    FrameLoopOptions options;
    std::function<void(const cv::Mat&, uint64_t)> process;
    std::unique_ptr<FrameSource> source;
    mutable std::mutex mutex;
    uint64_t dropped = 0, bad_frames = 0;
    LogThrottle bad_log;
    LogThrottle no_frame_log;  ///< simulated time: a tick whose frame never came
    std::deque<uint64_t> processing_ns, latency_ns;

    /// One usable frame to the node's work, timed: processing on the real clock (lab time
    /// stands still in a simulated tick), latency on the lab's.
    void handle(const cv::Mat& gray, uint64_t exposure_ns)
    {
        const auto start = std::chrono::steady_clock::now();
        process(gray, exposure_ns);
        const uint64_t done = get_time_ns();
        const auto took = std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - start).count();
        std::lock_guard<std::mutex> lock(mutex);
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
        ++bad_frames;
        uint64_t held = 0;
        if (bad_log.allow(get_time_ns(), held)) {
            CPM_LOG_WARN("%s: frame skipped: %s (%llu more since the last report)", options.who.c_str(), why.c_str(), (unsigned long long)held);
        }
    }

    void process_frame(const CameraFrame& f)
    {
        std::string why;
        cv::Mat gray = frame_image(f, options.camera, why);
        if (gray.empty()) {
            bad_frame(why);
            return;
        }
        handle(gray, f.header().create_stamp().nanoseconds());
    }

    /// The topic source: the newest frame of the camera in each batch; the others are dropped.
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
            dropped += mine - 1;
        }
        process_frame(*newest);
    }

    /// The topic source on the lab's simulated clock: one tick per camera frame, kSimulatedDetection_ns
    /// after the camera's. The camera wrote its frame before the clock moved on, but it may still
    /// be in flight: a tick with no new frame waits for one, up to 1 s of real time (a frame took
    /// more than 100 ms on a loaded machine, and that run differed). Once a frame did not come,
    /// 100 ms at most: the camera runs at another rate, and each tick between its frames would
    /// wait in vain. The first tick waits too: it takes the frame of lab time 0 (stamped 0 it was
    /// never "newer" than none, and which frame came first then depended on delivery).
    void run_simulated(const std::function<bool()>& stop_requested)
    {
        const auto period_ns = static_cast<uint64_t>(1e9 / options.frame_rate_hz);
        const uint64_t offset_ns = timer_ids::simulated_camera_offset_ns(period_ns) + std::min(kSimulatedDetection_ns, period_ns / 2);
        Reader<CameraFrame> frames(options.topic, options.reader);
        std::optional<uint64_t> last_stamp;  ///< the newest frame processed
        bool missed = false;                 ///< a tick's frame never came
        if (!wait_for_inputs(options.timer_id, {{options.topic, [&] { return frames.matched_publications(); }}}, stop_requested)) return;
        auto timer = Timer::create(options.timer_id, period_ns, offset_ns, TimerOptions{.wait_for_start = false, .simulated_time_allowed = true});
        timer->run_until(stop_requested, [&](uint64_t t) {
            auto newest = frames.get_sample(t);
            auto fresh = [&] { return newest.valid && (!last_stamp || newest.sample.header().create_stamp().nanoseconds() > *last_stamp); };
            const auto wait = std::chrono::milliseconds(missed ? 100 : 1000);
            const auto deadline = std::chrono::steady_clock::now() + wait;
            while (!fresh() && !stop_requested()) {
                const auto left = deadline - std::chrono::steady_clock::now();
                if (left <= std::chrono::nanoseconds(0)) break;
                (void)frames.wait_for_new_sample(left);
                newest = frames.get_sample(t);
            }
            if (!fresh()) {
                uint64_t held = 0;
                if (no_frame_log.allow(t, held)) {
                    CPM_LOG_WARN("%s: no new camera frame at lab time %.3f s within %lld ms; is its camera on the simulated clock at "
                                 "--rate %g Hz? (%llu more since the last report)",
                                 options.who.c_str(), double(t) * 1e-9, (long long)wait.count(), options.frame_rate_hz,
                                 (unsigned long long)held);
                }
                missed = true;
                return;
            }
            last_stamp = newest.sample.header().create_stamp().nanoseconds();
            process_frame(newest.sample);
        });
    }
};

FrameLoop::FrameLoop(FrameLoopOptions options, std::function<void(const cv::Mat&, uint64_t)> process)
    : impl_(std::make_unique<Impl>())
{
    Impl& d = *impl_;
    d.options = std::move(options);
    d.process = std::move(process);
    if (d.options.source != FrameSourceKind::topic && init_settings().simulated_time) {
        throw Error(d.options.who + ": --simulated_time takes frames from the " + d.options.topic + " topic only (its camera on the same clock); " +
                    d.options.path + " is read in real time");
    }
    switch (d.options.source) {
    case FrameSourceKind::device: d.source = open_device(d.options.path); break;
    case FrameSourceKind::video: d.source = open_video(d.options.path); break;
    case FrameSourceKind::images: d.source = open_images(d.options.path, d.options.fps); break;
    case FrameSourceKind::topic: break;
    }
}

FrameLoop::~FrameLoop() = default;

void FrameLoop::run(const std::function<bool()>& stop_requested, const std::function<void()>& before_replay)
{
    Impl& d = *impl_;
    if (d.options.source == FrameSourceKind::topic && init_settings().simulated_time) {
        d.run_simulated(stop_requested);
        return;
    }
    if (d.options.source == FrameSourceKind::topic) {
        // Depth 8: frames that pile up while one is processed arrive in the next batch and are
        // counted as dropped (more than 8 in one processing time are dropped uncounted).
        ReaderOptions ro = d.options.reader;
        ro.history_depth = 8;
        AsyncReader<CameraFrame> frames([&d](std::vector<CameraFrame>& batch) { d.on_frames(batch); }, d.options.topic, ro);
        while (!stop_requested()) std::this_thread::sleep_for(std::chrono::milliseconds(20));
        frames.stop();
        return;
    }
    if (d.options.source == FrameSourceKind::video || d.options.source == FrameSourceKind::images) before_replay();
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
        d.handle(gray, get_time_ns());
    }
}

uint64_t FrameLoop::dropped() const
{
    std::lock_guard<std::mutex> lock(impl_->mutex);
    return impl_->dropped;
}

FrameTimes FrameLoop::times() const
{
    std::lock_guard<std::mutex> lock(impl_->mutex);
    const std::vector<uint64_t> proc(impl_->processing_ns.begin(), impl_->processing_ns.end());
    const std::vector<uint64_t> lat(impl_->latency_ns.begin(), impl_->latency_ns.end());
    return {percentile(proc, 0.5) * 1e-6, percentile(proc, 0.99) * 1e-6, percentile(lat, 0.5) * 1e-6, percentile(lat, 0.99) * 1e-6};
}

uint64_t FrameLoop::bad_frames() const
{
    std::lock_guard<std::mutex> lock(impl_->mutex);
    return impl_->bad_frames;
}

}  // namespace cpm::aruco
