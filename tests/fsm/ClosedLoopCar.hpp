#pragma once
// A simulated car (FirmwareSim: vehicle model, rangers, walls) and the bridge's command path
// joined in-process, stepped at 50 Hz: what a state machine sees of the car, and its commands
// sent back as VehicleCommandDirect. Shared by the closed-loop tests of fsm and aruco.
#include <cpm/fsm/Machine.hpp>
#include <cpm/vehicle/BridgeCore.hpp>
#include <cpm/vehicle/FirmwareSim.hpp>

#include <cstdint>

namespace cpm_test {

class ClosedLoopCar
{
public:
    /// `seed`: the simulator's sensor noise.
    ClosedLoopCar(const cpm::vehicle::VehicleParameters& params, const cpm::vehicle::World& world, cpm::vehicle::Pose start,
                  uint32_t seed = 1)
        : params_(params), car_(params, world, start, 1, seed), bridge_(1, cpm::vehicle::Calibration{}, start)
    {
    }

    /// 20 ms on; the inputs from the state packet the car then sends (no markers).
    cpm::fsm::Inputs step()
    {
        for (int i = 0; i < 5; ++i) car_.step();
        t_ns_ += 20'000'000;
        packet_ = car_.make_state_packet();
        cpm::fsm::Inputs in;
        in.t = t_ns_ * 1e-9;
        in.odometer = packet_.odometer_steps / params_.ticks_per_metre;
        in.yaw = packet_.imu_yaw_e4 * 1e-4;
        in.speed = packet_.speed_mm_s * 1e-3;
        in.front = packet_.us_front_mm * 1e-3;
        in.left = packet_.us_left_mm * 1e-3;
        in.right = packet_.us_right_mm * 1e-3;
        return in;
    }

    /// The machine's output, through the bridge's checks and protocol, into the car.
    void command(const cpm::fsm::Output& out)
    {
        cpm::vehicle::CommandInputs commands;
        VehicleCommandDirect direct;
        direct.vehicle_id(1);
        direct.motor_throttle(out.throttle);
        direct.steering_servo(out.steering);
        direct.header().create_stamp().nanoseconds(t_ns_);
        commands.direct = {direct, 0, true};
        auto frame = cpm::vehicle::encode_frame(bridge_.on_state_packet(packet_, t_ns_, commands).command);
        car_.receive(frame.data(), frame.size());
    }

    const cpm::vehicle::FirmwareSim& car() const { return car_; }
    const cpm::vehicle::Pose& pose() const { return car_.model().pose(); }

private:
    cpm::vehicle::VehicleParameters params_;
    cpm::vehicle::FirmwareSim car_;
    cpm::vehicle::BridgeCore bridge_;
    uint64_t t_ns_ = 1'000'000'000;
    decltype(car_.make_state_packet()) packet_{};
};

}  // namespace cpm_test
