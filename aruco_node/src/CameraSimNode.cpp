#include <cpm/aruco/CameraSimNode.hpp>

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

#include <CameraFrame.h>
#include <VehicleObservation.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <vector>

namespace cpm::aruco {

struct CameraSimNode::Impl
{
    explicit Impl(CameraSimOptions o)
        : options(std::move(o)), renderer(options.world, options.camera, options.render),
          poses(topics::vehicle_observation.name, topics::vehicle_observation.reader_for(options.vehicle_id)),
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
                CPM_LOG_WARN("camera_sim %u: no VehicleObservation of the car yet; no frame", unsigned(options.vehicle_id));
            }
            return;
        }
        // The exposure is now: the newest pose moved on by the motion between the last two
        // (observations come at 50 Hz; up to 100 ms ahead).
        const uint64_t stamp = pose.sample.header().create_stamp().nanoseconds();
        const auto& p = pose.sample.pose();
        if (stamp != newest_stamp) {
            previous = newest;
            previous_stamp = newest_stamp;
            newest = {p.x(), p.y(), p.yaw()};
            newest_stamp = stamp;
        }
        vehicle::Pose at = newest;
        uint64_t exposure = newest_stamp;
        if (previous_stamp && newest_stamp > previous_stamp && now > newest_stamp && now - newest_stamp <= 100'000'000) {
            const double k = double(now - newest_stamp) / double(newest_stamp - previous_stamp);
            at.x += k * (newest.x - previous.x);
            at.y += k * (newest.y - previous.y);
            at.yaw += k * std::remainder(newest.yaw - previous.yaw, 2 * M_PI);
            exposure = now;
        }
        renderer.render(at, image);
        message.header().create_stamp().nanoseconds(exposure);
        message.header().valid_after_stamp().nanoseconds(exposure);
        auto& data = message.data();
        data.resize(image.total());
        std::memcpy(data.data(), image.data, image.total());
        (void)frames.write(message);
        std::lock_guard<std::mutex> lock(mutex);
        ++count;
        render_ns.push_back(uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - started).count()));
        if (render_ns.size() > 100000) render_ns.erase(render_ns.begin(), render_ns.begin() + 50000);
    }

    CameraSimOptions options;
    Renderer renderer;
    Reader<VehicleObservation> poses;
    Writer<CameraFrame> frames;
    CameraFrame message;
    cv::Mat image;
    vehicle::Pose newest, previous;
    uint64_t newest_stamp = 0, previous_stamp = 0;
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
        !wait_for_inputs(node_id, {{topics::vehicle_observation.name, [&] { return impl_->poses.matched_publications(); }}},
                         stop_requested)) {
        return;
    }
    auto timer = Timer::create(node_id, period_ns, 0,
                               TimerOptions{.wait_for_start = false, .simulated_time_allowed = true});
    timer->run_until(stop_requested, [&](uint64_t) { impl_->tick(); });
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

}  // namespace cpm::aruco
