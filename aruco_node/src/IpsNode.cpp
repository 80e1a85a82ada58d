#include <cpm/aruco/IpsNode.hpp>

#include "FrameLoop.hpp"

#include <cpm/LogThrottle.hpp>
#include <cpm/Logging.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/timer_ids.hpp>
#include <cpm/topics.hpp>

#include <chrono>
#include <cstdio>
#include <mutex>
#include <set>

namespace cpm::aruco {

std::vector<VehicleObservation> observations_of(const OverheadView& view, uint64_t exposure_ns)
{
    std::vector<VehicleObservation> out;
    for (const auto& car : view.cars) {
        VehicleObservation o;
        o.vehicle_id(uint8_t(car.vehicle_id));
        o.header().create_stamp().nanoseconds(exposure_ns);
        o.header().valid_after_stamp().nanoseconds(exposure_ns);
        o.pose().x(car.x);
        o.pose().y(car.y);
        o.pose().yaw(car.yaw);
        out.push_back(o);
    }
    return out;
}

struct IpsNode::Impl
{
    explicit Impl(IpsNodeOptions o)
        : options(std::move(o)), locator(options.world, options.camera, options.detector),
          writer(topics::vehicle_observation.name, topics::vehicle_observation.writer),
          loop(FrameLoopOptions{.who = "ips_node",
                                .timer_id = timer_ids::ips_node,
                                .topic = topics::ips_camera_frame.name,
                                .reader = topics::ips_camera_frame.reader_for(0),
                                .vehicle_id = 0,
                                .camera = options.camera,
                                .source = options.source,
                                .path = options.path,
                                .fps = options.fps,
                                .frame_rate_hz = options.frame_rate_hz},
               [this](const cv::Mat& gray, uint64_t exposure_ns) { process(gray, exposure_ns); })
    {
    }

    void process(const cv::Mat& gray, uint64_t exposure_ns)
    {
        const OverheadView view = locator.locate(gray);
        const auto observations = observations_of(view, exposure_ns);
        for (const auto& o : observations) (void)writer.write(o);
        const uint64_t done = get_time_ns();
        std::lock_guard<std::mutex> lock(mutex);
        ++counts.frames;
        counts.observations += observations.size();
        counts.seen_twice += view.seen_twice.size();
        counts.misfits += view.misfits.size();
        counts.floor_residual_px = view.floor_residual_px;
        for (int id : view.unknown_ids) {
            ++counts.unknown_markers;
            if (unknown_logged.insert(id).second) {
                CPM_LOG_WARN("ips_node: marker %d is on no car's roof and no floor marker of the world (counted, logged once)", id);
            }
        }
        uint64_t held = 0;
        if (!view.seen_twice.empty() && twice_log.allow(done, held)) {
            CPM_LOG_WARN("ips_node: roof marker %d seen %s in one frame: two cars wear it, or a copy lies around; not published "
                         "(%llu more since the last report)",
                         view.seen_twice[0], "twice", (unsigned long long)held);
        }
        if (!view.misfits.empty() && misfit_log.allow(done, held)) {
            CPM_LOG_WARN("ips_node: roof marker %d does not measure its size on the roof's plane (is the world's z right?); not "
                         "published (%llu more since the last report)",
                         view.misfits[0], (unsigned long long)held);
        }
        if (view.floor_residual_px > options.moved_px) {
            ++counts.moved_frames;
            if (moved_log.allow(done, held)) {
                CPM_LOG_WARN("ips_node: the floor markers are %.1f px from where the camera file puts them (over %.1f px): the camera "
                             "moved since it was located; locate it again (cpm camera locate) (%llu more since the last report)",
                             view.floor_residual_px, options.moved_px, (unsigned long long)held);
            }
        }
    }

    IpsNodeOptions options;
    OverheadLocator locator;
    Writer<VehicleObservation> writer;
    mutable std::mutex mutex;
    IpsNodeStats counts;
    std::set<int> unknown_logged;
    LogThrottle twice_log, misfit_log, moved_log;
    FrameLoop loop;  ///< last: its thread calls process()
};

IpsNode::IpsNode(IpsNodeOptions options) : impl_(std::make_unique<Impl>(std::move(options))) {}

IpsNode::~IpsNode() = default;

void IpsNode::run(const std::function<bool()>& stop_requested)
{
    Impl& d = *impl_;
    d.loop.run(stop_requested, [&d] { (void)d.writer.wait_for_matched(1, std::chrono::seconds(3)); });
}

IpsNodeStats IpsNode::stats() const
{
    IpsNodeStats c;
    {
        std::lock_guard<std::mutex> lock(impl_->mutex);
        c = impl_->counts;
    }
    c.dropped = impl_->loop.dropped();
    c.bad_frames = impl_->loop.bad_frames();
    return c;
}

std::string IpsNode::stats_json() const
{
    const IpsNodeStats c = stats();
    const FrameTimes t = impl_->loop.times();
    char line[768];
    std::snprintf(line, sizeof line,
                  "{\"frames\": %llu, \"dropped\": %llu, \"bad_frames\": %llu, \"observations\": %llu, \"unknown_markers\": %llu, "
                  "\"seen_twice\": %llu, \"misfits\": %llu, \"moved_frames\": %llu, \"floor_residual_px\": %.3f, "
                  "\"processing_ms_p50\": %.3f, \"processing_ms_p99\": %.3f, \"latency_ms_p50\": %.3f, \"latency_ms_p99\": %.3f}",
                  (unsigned long long)c.frames, (unsigned long long)c.dropped, (unsigned long long)c.bad_frames,
                  (unsigned long long)c.observations, (unsigned long long)c.unknown_markers, (unsigned long long)c.seen_twice,
                  (unsigned long long)c.misfits, (unsigned long long)c.moved_frames, c.floor_residual_px, t.processing_ms_p50,
                  t.processing_ms_p99, t.latency_ms_p50, t.latency_ms_p99);
    return line;
}

}  // namespace cpm::aruco
