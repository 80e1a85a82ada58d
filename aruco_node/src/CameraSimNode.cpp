#include <cpm/aruco/CameraSimNode.hpp>

#include <cpm/Error.hpp>
#include <cpm/LogThrottle.hpp>
#include <cpm/MultiVehicleReader.hpp>
#include <cpm/aruco/Overhead.hpp>
#include <cpm/Logging.hpp>
#include <cpm/Reader.hpp>
#include <cpm/Timer.hpp>
#include <cpm/timer_ids.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/init.hpp>
#include <cpm/percentile.hpp>
#include <cpm/topics.hpp>

#include <CameraFrame.h>
#include <VehicleObservation.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <mutex>
#include <vector>

namespace cpm::aruco {
namespace {

/// A car's true pose moved on to the frame's moment by its motion between its last two
/// observations (they come at 50 Hz; up to 100 ms ahead).
class PoseAhead
{
public:
    /// `stamp`: the newest observation's create_stamp. Returns the pose at `now` and sets
    /// `exposure` to the moment it is for.
    vehicle::Pose at(const vehicle::Pose& newest_pose, uint64_t stamp, uint64_t now, uint64_t& exposure)
    {
        // A first observation may be stamped 0 (the simulated clock's start): not "the same one".
        if (!any_ || stamp != newest_stamp_) {
            previous_ = newest_;
            previous_stamp_ = any_ ? newest_stamp_ : 0;
            has_previous_ = any_;
            newest_ = newest_pose;
            newest_stamp_ = stamp;
            any_ = true;
        }
        vehicle::Pose p = newest_;
        exposure = newest_stamp_;
        if (has_previous_ && newest_stamp_ > previous_stamp_ && now > newest_stamp_ && now - newest_stamp_ <= 100'000'000) {
            const double k = double(now - newest_stamp_) / double(newest_stamp_ - previous_stamp_);
            p.x += k * (newest_.x - previous_.x);
            p.y += k * (newest_.y - previous_.y);
            p.yaw += k * std::remainder(newest_.yaw - previous_.yaw, 2 * M_PI);
            exposure = now;
        }
        return p;
    }

private:
    vehicle::Pose newest_, previous_;
    uint64_t newest_stamp_ = 0, previous_stamp_ = 0;
    bool any_ = false, has_previous_ = false;
};

/// Where a simulated camera's tick falls in its period: on the simulated clock a step after the
/// car's simulator (timer_ids), in real time at its start.
uint64_t tick_offset_ns(uint64_t period_ns) { return init_settings().simulated_time ? timer_ids::simulated_camera_offset_ns(period_ns) : 0; }

/// The frame's bytes and stamps from a mono8 image.
void fill_frame(CameraFrame& message, const cv::Mat& image, uint64_t exposure)
{
    message.header().create_stamp().nanoseconds(exposure);
    message.header().valid_after_stamp().nanoseconds(exposure);
    auto& data = message.data();
    data.resize(image.total());
    std::memcpy(data.data(), image.data, image.total());
}

/// Render times, bounded.
void keep_time(std::vector<uint64_t>& times, std::chrono::steady_clock::time_point started)
{
    times.push_back(uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - started).count()));
    if (times.size() > 100000) times.erase(times.begin(), times.begin() + 50000);
}

}  // namespace

struct CameraSimNode::Impl
{
    explicit Impl(CameraSimOptions o)
        : options(std::move(o)), renderer(options.world, options.camera, options.render),
          poses(options.truth_topic, topics::vehicle_observation.reader_for(options.vehicle_id)),
          frames(topics::camera_frame.name, topics::camera_frame.writer)
    {
        message.vehicle_id(options.vehicle_id);
        message.width(uint32_t(options.camera.width));
        message.height(uint32_t(options.camera.height));
        message.encoding("mono8");
    }

    void tick()
    {
        const uint64_t now = get_time_ns();  // the lab's clock: real, or simulated under --simulated_time
        const auto started = std::chrono::steady_clock::now();
        auto pose = poses.get_sample(now);
        if (!pose.valid) {
            std::lock_guard<std::mutex> lock(mutex);
            ++without_pose;
            uint64_t held = 0;
            if (no_pose_log.allow(now, held)) {
                CPM_LOG_WARN("camera_sim %u: no VehicleObservation of the car on %s yet; no frame", unsigned(options.vehicle_id),
                             options.truth_topic.c_str());
            }
            return;
        }
        uint64_t exposure = 0;
        const auto& p = pose.sample.pose();
        const vehicle::Pose at = ahead.at({p.x(), p.y(), p.yaw()}, pose.sample.header().create_stamp().nanoseconds(), now, exposure);
        renderer.render(at, image);
        fill_frame(message, image, exposure);
        (void)frames.write(message);
        std::lock_guard<std::mutex> lock(mutex);
        ++count;
        keep_time(render_ns, started);
    }

    CameraSimOptions options;
    Renderer renderer;
    Reader<VehicleObservation> poses;
    Writer<CameraFrame> frames;
    CameraFrame message;
    cv::Mat image;
    PoseAhead ahead;
    mutable std::mutex mutex;
    uint64_t count = 0, without_pose = 0;
    std::vector<uint64_t> render_ns;
    LogThrottle no_pose_log;
};

CameraSimNode::CameraSimNode(CameraSimOptions options) : impl_(std::make_unique<Impl>(std::move(options))) {}

CameraSimNode::~CameraSimNode() = default;

void CameraSimNode::run(const std::function<bool()>& stop_requested)
{
    const auto period_ns = static_cast<uint64_t>(1e9 / impl_->options.rate_hz);
    const std::string node_id = timer_ids::camera_sim(impl_->options.vehicle_id);
    // On the simulated clock: the car's true pose must reach the first frame.
    if (init_settings().simulated_time &&
        !wait_for_inputs(node_id, {{impl_->options.truth_topic, [&] { return impl_->poses.matched_publications(); }}},
                         stop_requested)) {
        return;
    }
    // And its frames must reach their reader (the marker finder): a best-effort writer sends
    // only to the readers it has matched itself, which on a loaded machine came after the frame
    // of lab time 0 had gone to no one (the finder waited 1 s for it in vain, and the run
    // differed). Without any reader after 5 s it says so and runs.
    if (init_settings().simulated_time) {
        const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
        while (!impl_->frames.wait_for_matched(1, std::chrono::milliseconds(100))) {
            if (stop_requested()) return;
            if (std::chrono::steady_clock::now() >= deadline) {
                CPM_LOG_WARN("camera_sim %u: no reader of %s after 5 s; joining the lab clock without one",
                             unsigned(impl_->options.vehicle_id), topics::camera_frame.name);
                break;
            }
        }
    }
    auto timer = Timer::create(node_id, period_ns, tick_offset_ns(period_ns),
                               TimerOptions{.wait_for_start = false, .simulated_time_allowed = true});
    bool first_tick = init_settings().simulated_time;
    timer->run_until(stop_requested, [&](uint64_t t) {
        // The first tick comes a step after the car simulator's first, which wrote its pose then;
        // but that pose may still be on its way. Without waiting (1 s of real time at most: 100 ms
        // ran out on a loaded machine) whether the first frame was rendered depended on delivery.
        if (first_tick) {
            first_tick = false;
            const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(1);
            while (!impl_->poses.get_sample(t).valid && !stop_requested()) {
                const auto left = deadline - std::chrono::steady_clock::now();
                if (left <= std::chrono::nanoseconds(0)) break;
                (void)impl_->poses.wait_for_new_sample(left);
            }
        }
        impl_->tick();
    });
}

std::string CameraSimNode::stats_json() const
{
    std::lock_guard<std::mutex> lock(impl_->mutex);
    char line[256];
    std::snprintf(line, sizeof line, "{\"vehicle_id\": %u, \"frames\": %llu, \"without_pose\": %llu, \"render_ms_p50\": %.3f}",
                  unsigned(impl_->options.vehicle_id), (unsigned long long)impl_->count, (unsigned long long)impl_->without_pose,
                  percentile(impl_->render_ns, 0.5) * 1e-6);
    return line;
}

// ---------------------------------------------------------------------------------------------

struct OverheadCameraSimNode::Impl
{
    static std::vector<uint8_t> cars_of(const vehicle::World& world)
    {
        std::vector<uint8_t> ids;
        for (const auto& r : world.roof_markers()) ids.push_back(uint8_t(r.vehicle_id));
        if (ids.empty()) throw Error("camera_sim --overhead: the world has no roof_markers (which marker is on which car)");
        return ids;
    }

    explicit Impl(CameraSimOptions o)
        : options(std::move(o)), renderer(options.world, options.camera, options.render),
          poses(options.truth_topic, cars_of(options.world), topics::vehicle_observation.reader),
          frames(topics::ips_camera_frame.name, topics::ips_camera_frame.writer)
    {
        message.vehicle_id(0);
        message.width(uint32_t(options.camera.width));
        message.height(uint32_t(options.camera.height));
        message.encoding("mono8");
    }

    void tick()
    {
        const uint64_t now = get_time_ns();
        const auto started = std::chrono::steady_clock::now();
        cars.clear();
        for (auto& [id, result] : poses.get_samples(now)) {
            if (!result.valid) continue;
            uint64_t exposure = 0;
            const auto& p = result.sample.pose();
            cars.push_back({id, ahead[id].at({p.x(), p.y(), p.yaw()}, result.sample.header().create_stamp().nanoseconds(), now, exposure)});
        }
        renderer.render(cars, image);
        fill_frame(message, image, now);
        (void)frames.write(message);
        std::lock_guard<std::mutex> lock(mutex);
        ++count;
        drawn += cars.size();
        keep_time(render_ns, started);
    }

    CameraSimOptions options;
    OverheadRenderer renderer;
    MultiVehicleReader<VehicleObservation> poses;
    Writer<CameraFrame> frames;
    CameraFrame message;
    cv::Mat image;
    std::vector<OverheadCar> cars;
    std::map<int, PoseAhead> ahead;
    mutable std::mutex mutex;
    uint64_t count = 0, drawn = 0;
    std::vector<uint64_t> render_ns;
};

OverheadCameraSimNode::OverheadCameraSimNode(CameraSimOptions options) : impl_(std::make_unique<Impl>(std::move(options))) {}

OverheadCameraSimNode::~OverheadCameraSimNode() = default;

void OverheadCameraSimNode::run(const std::function<bool()>& stop_requested)
{
    const auto period_ns = static_cast<uint64_t>(1e9 / impl_->options.rate_hz);
    if (init_settings().simulated_time &&
        !wait_for_inputs(timer_ids::ips_camera, {{impl_->options.truth_topic, [&] { return impl_->poses.matched_publications(); }}},
                         stop_requested)) {
        return;
    }
    auto timer = Timer::create(timer_ids::ips_camera, period_ns,
                               tick_offset_ns(period_ns), TimerOptions{.wait_for_start = false, .simulated_time_allowed = true});
    timer->run_until(stop_requested, [&](uint64_t) { impl_->tick(); });
}

std::string OverheadCameraSimNode::stats_json() const
{
    std::lock_guard<std::mutex> lock(impl_->mutex);
    char line[256];
    std::snprintf(line, sizeof line, "{\"frames\": %llu, \"cars_drawn\": %llu, \"render_ms_p50\": %.3f}", (unsigned long long)impl_->count,
                  (unsigned long long)impl_->drawn, percentile(impl_->render_ns, 0.5) * 1e-6);
    return line;
}

}  // namespace cpm::aruco
