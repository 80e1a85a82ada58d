// What the vehicle end-to-end tests share: one car as two real processes (a microcontroller -
// firmware_sim, or the real firmware under firmware_hil - and vehicle_bridge) joined by a real
// pseudo-terminal, a watcher of what the car publishes, a command repeater and the geometry
// the checks use.
#pragma once
#include <cpm/Participant.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/stamp_message.hpp>

#include <cpm_test/Dds.hpp>
#include <cpm_test/Gaps.hpp>
#include <cpm_test/Isolation.hpp>
#include <cpm_test/Process.hpp>

#include <nlohmann/json.hpp>

#include <VehicleCommandSpeedCurvature.h>
#include <VehicleObservation.h>
#include <VehicleState.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <fcntl.h>
#include <random>
#include <unistd.h>
#include <cmath>
#include <memory>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace car_harness {


using namespace std::chrono_literals;
using cpm_test::built_program;
using cpm_test::Process;
inline constexpr uint8_t kId = 7;
inline constexpr uint64_t kSecond = 1'000'000'000ull;

inline size_t count_of(const std::string& text, const std::string& what)
{
    size_t n = 0;
    for (size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
    return n;
}

/// Which program plays the car's microcontroller: firmware_sim, or firmware_hil running the
/// real firmware. Both take the same flags, print `device: PATH` first and their statistics last.
enum class Microcontroller { sim, avr };

/// One simulated car: its microcontroller on a pty, vehicle_bridge on its device.
struct Car
{
    std::unique_ptr<Process> sim;
    std::unique_ptr<Process> bridge;
    std::string device;
    uint8_t id = kId;
    Microcontroller microcontroller = Microcontroller::sim;

    explicit Car(std::vector<std::string> sim_flags = {}, bool start_bridge = true, uint8_t vehicle_id = kId,
                 Microcontroller mc = Microcontroller::sim)
        : id(vehicle_id), microcontroller(mc)
    {
        start_sim(std::move(sim_flags));
        if (start_bridge) this->start_bridge();
    }
    void start_sim(std::vector<std::string> flags)
    {
        // As a real car's: the microcontroller's loop and the bridge's serial loop in real time.
        std::vector<std::string> argv{built_program(microcontroller == Microcontroller::avr ? "firmware_hil" : "firmware_sim"),
                                      "--vehicle_id", std::to_string(id), "--realtime"};
        argv.insert(argv.end(), flags.begin(), flags.end());
        sim = std::make_unique<Process>(argv);
        EXPECT_TRUE(cpm_test::wait_until([&] { return sim->output().find('\n') != std::string::npos; }))
            << sim->errors();
        auto out = sim->output();
        device = out.rfind("device: ", 0) == 0 ? out.substr(8, out.find('\n') - 8) : "";
        ASSERT_FALSE(device.empty()) << out << sim->errors();
    }
    void start_bridge(const std::string& path = {}, int bridge_id = -1)
    {
        bridge = std::make_unique<Process>(std::vector<std::string>{built_program("vehicle_bridge"), "--vehicle_id",
                                                                    std::to_string(bridge_id < 0 ? id : bridge_id),
                                                                    "--device", path.empty() ? device : path, "--realtime"});
    }
    /// The sim's `pwm T MODE PWM` trace lines after time t (ns): (time, mode) pairs.
    std::vector<std::pair<uint64_t, int>> pwm_trace_after(uint64_t t) const
    {
        return pwm_trace_after(t, -1);
    }
    /// The same, only the lines with this mode (0 brake, 1 forward, 2 reverse; -1 any).
    std::vector<std::pair<uint64_t, int>> pwm_trace_after(uint64_t t, int only_mode) const
    {
        std::vector<std::pair<uint64_t, int>> out;
        std::istringstream in(sim->output());
        for (std::string word; in >> word;) {
            if (word != "pwm") continue;
            unsigned long long time = 0;
            int mode = 0, pwm = 0;
            in >> time >> mode >> pwm;
            if (time > t && (only_mode < 0 || mode == only_mode)) out.emplace_back(time, mode);
        }
        return out;
    }
    /// How often the motor went from forward to brake in the trace: the car's stops while it
    /// drove (a stop of a standing car, as the watchdog's before the first command, is not one).
    int stops_while_driving() const
    {
        int stops = 0, mode = -1;
        for (const auto& [t, m] : pwm_trace_after(0)) {
            stops += mode == 1 && m == 0;
            mode = m;
        }
        return stops;
    }
};

/// Collects every VehicleObservation and VehicleState of the car as it arrives.
class Watcher
{
public:
    explicit Watcher(cpm::Participant& p)
        : observations_(p, "vehicleObservation", {.keep_all = true}), states_(p, "vehicleState", {.keep_all = true}),
          thread_([this] { run(); })
    {
    }
    ~Watcher()
    {
        stop_ = true;
        thread_.join();
    }
    std::vector<VehicleObservation> observations() const
    {
        std::lock_guard<std::mutex> lock(mutex_);
        return observation_log_;
    }
    std::vector<VehicleState> states() const
    {
        std::lock_guard<std::mutex> lock(mutex_);
        return state_log_;
    }
    /// States created at or after t.
    size_t states_created_after(uint64_t t) const
    {
        size_t n = 0;
        for (auto& s : states()) n += s.header().create_stamp().nanoseconds() >= t;
        return n;
    }
    /// The gaps over 30 ms between the stamps of consecutive states created in [t0, t1), for a
    /// failed rate check to say where the states went missing ("none" when there is none).
    std::string state_gaps_between(uint64_t t0, uint64_t t1) const
    {
        std::vector<uint64_t> stamps;
        for (auto& s : states()) {
            const uint64_t t = s.header().create_stamp().nanoseconds();
            if (t >= t0 && t < t1) stamps.push_back(t);
        }
        return cpm_test::gaps_over(std::move(stamps), t0, 30'000'000ull);
    }
    /// Observations created in [t0, t1).
    std::vector<VehicleObservation> observations_between(uint64_t t0, uint64_t t1) const
    {
        std::vector<VehicleObservation> out;
        for (auto& o : observations()) {
            uint64_t t = o.header().create_stamp().nanoseconds();
            if (t >= t0 && t < t1) out.push_back(o);
        }
        return out;
    }
    bool wait_for_states(size_t n, std::chrono::milliseconds timeout = 10s) const
    {
        return cpm_test::wait_until([&] { return states().size() >= n; }, timeout);
    }

private:
    void run()
    {
        while (!stop_) {
            auto o = observations_.take();
            auto s = states_.take();
            {
                std::lock_guard<std::mutex> lock(mutex_);
                observation_log_.insert(observation_log_.end(), o.begin(), o.end());
                state_log_.insert(state_log_.end(), s.begin(), s.end());
            }
            std::this_thread::sleep_for(2ms);
        }
    }

    cpm::ReaderAbstract<VehicleObservation> observations_;
    cpm::ReaderAbstract<VehicleState> states_;
    mutable std::mutex mutex_;
    std::vector<VehicleObservation> observation_log_;
    std::vector<VehicleState> state_log_;
    std::atomic<bool> stop_{false};
    std::thread thread_;
};

/// Writes a command for the car at 20 Hz from a thread of the test until destroyed.
template <class T>
class Repeater
{
public:
    Repeater(cpm::Participant& p, const std::string& topic, T command, uint8_t vehicle_id = kId)
        : writer_(p, topic), command_(with_id(std::move(command), vehicle_id)), thread_([this] { run(); })
    {
    }
    ~Repeater()
    {
        stop_ = true;
        thread_.join();
    }

private:
    // The id is set before the thread starts (set after, the first command went to car 0 and
    // raced with the thread's write).
    static T with_id(T command, uint8_t vehicle_id)
    {
        command.vehicle_id(vehicle_id);
        return command;
    }
    void run()
    {
        while (!stop_) {
            cpm::stamp_message(command_, cpm::get_time_ns(), 0);
            (void)writer_.write(command_);
            std::this_thread::sleep_for(50ms);
        }
    }
    cpm::Writer<T> writer_;
    T command_;
    std::atomic<bool> stop_{false};
    std::thread thread_;
};

inline VehicleCommandSpeedCurvature speed_curvature(double speed, double curvature)
{
    VehicleCommandSpeedCurvature c;
    c.speed(speed);
    c.curvature(curvature);
    return c;
}

/// Radius of the circle through the points (Kåsa's algebraic least-squares fit).
inline double fitted_radius(const std::vector<VehicleObservation>& points)
{
    double n = double(points.size()), sx = 0, sy = 0, sxx = 0, syy = 0, sxy = 0, sxz = 0, syz = 0, sz = 0;
    for (auto& o : points) {
        double x = o.pose().x(), y = o.pose().y(), z = x * x + y * y;
        sx += x, sy += y, sxx += x * x, syy += y * y, sxy += x * y, sxz += x * z, syz += y * z, sz += z;
    }
    // Solve [sxx sxy sx; sxy syy sy; sx sy n] [a b c] = [sxz syz sz] for x^2+y^2 = a x + b y + c.
    double m[3][4] = {{sxx, sxy, sx, sxz}, {sxy, syy, sy, syz}, {sx, sy, n, sz}};
    for (int i = 0; i < 3; ++i) {
        for (int j = i + 1; j < 3; ++j) {
            double f = m[j][i] / m[i][i];
            for (int k = i; k < 4; ++k) m[j][k] -= f * m[i][k];
        }
    }
    double c = m[2][3] / m[2][2];
    double b = (m[1][3] - m[1][2] * c) / m[1][1];
    double a = (m[0][3] - m[0][1] * b - m[0][2] * c) / m[0][0];
    return std::sqrt(c + a * a / 4 + b * b / 4);
}

/// The last line of a program's output that is a JSON object (its statistics); null if none.
inline nlohmann::json last_json_line(const std::string& output)
{
    nlohmann::json last;
    std::istringstream in(output);
    for (std::string line; std::getline(in, line);) {
        if (!line.empty() && line[0] == '{') last = nlohmann::json::parse(line);
    }
    return last;
}

/// Mean speed along the observed path: its length over the time its stamps span.
inline double mean_speed(const std::vector<VehicleObservation>& points)
{
    double length = 0;
    for (size_t i = 1; i < points.size(); ++i) {
        length += std::hypot(points[i].pose().x() - points[i - 1].pose().x(), points[i].pose().y() - points[i - 1].pose().y());
    }
    double dt = double(points.back().header().create_stamp().nanoseconds() -
                       points.front().header().create_stamp().nanoseconds()) * 1e-9;
    return length / dt;
}

/// Forty bursts of 37 random bytes (one zero among them) into the line towards the car's
/// microcontroller, 50 ms apart: between the bridge's commands.
inline void write_garbage_bursts(const std::string& device)
{
    int line = ::open(device.c_str(), O_WRONLY | O_NOCTTY);
    ASSERT_GE(line, 0);
    std::mt19937 rng(7);
    for (int burst = 0; burst < 40; ++burst) {
        uint8_t junk[37];
        for (auto& b : junk) b = uint8_t(rng());
        junk[10] = 0;
        ASSERT_EQ(::write(line, junk, sizeof junk), ssize_t(sizeof junk));
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    ::close(line);
}

/// With one state frame in five corrupted on its way to the bridge: still publishing at the
/// rate the corruption leaves (80 of the 100 states of two seconds, binomial sd 4; at least 60,
/// counted by their stamps once they have arrived - a broken link gives none), and still driving
/// at the commanded 0.5 m/s.
inline void expect_driving_through_corruption(const Watcher& watch)
{
    const uint64_t t0 = cpm::get_time_ns();
    auto states_in_two_seconds = [&] { return watch.states_created_after(t0) - watch.states_created_after(t0 + 2 * kSecond); };
    EXPECT_TRUE(cpm_test::wait_until([&] { return states_in_two_seconds() >= 60; }, std::chrono::seconds(6))) << states_in_two_seconds();
    auto recent = watch.observations_between(t0, t0 + kSecond / 2);
    ASSERT_GT(recent.size(), 10u);
    EXPECT_NEAR(mean_speed(recent), 0.5, 0.1);
}

}  // namespace car_harness
