#pragma once
#include <cpm/vehicle/Protocol.hpp>
#include <cpm/vehicle/VehicleModel.hpp>
#include <cpm/vehicle/World.hpp>

#include <cstdint>
#include <random>
#include <utility>
#include <vector>

namespace cpm::vehicle {

/// What the simulated microcontroller has seen so far.
struct FirmwareStats
{
    uint64_t commands = 0;          ///< valid commands for this vehicle
    uint64_t wrong_vehicle = 0;     ///< valid commands for another vehicle id (ignored)
    uint64_t watchdog_stops = 0;    ///< times the watchdog braked the motor
    uint64_t state_packets = 0;     ///< state packets produced
    uint64_t unanswered_states = 0; ///< state packets not answered by a command before the next one
    uint64_t wall_collisions = 0;   ///< times the body ran into a wall (each contact counted once)
    DecoderErrors decoder;
};

/// The car's body ran into a wall: where it stopped and which wall.
struct Collision
{
    double t = 0;  ///< model time, s
    Pose pose;
    Segment wall;
};

/// "vehicle N: hit the wall [x1, y1, x2, y2] at x … y … yaw …; stopped against it", as the
/// simulators log it.
std::string describe_collision(uint8_t vehicle_id, const Collision& c);

/// The car's microcontroller without its serial port or clock: the vehicle model, its
/// sensors against the world, the command decoder and the watchdog. firmware_sim drives it
/// in real time behind a pty; tests drive it step by step. Not thread-safe.
class FirmwareSim
{
public:
    FirmwareSim(const VehicleParameters& parameters, World world, Pose start, uint8_t vehicle_id, uint32_t seed);

    /// Bytes from the host (any chunking); commands act on the model from now.
    void receive(const uint8_t* data, size_t size);
    /// The motor and servo as a real microcontroller's pins show them (firmware_hil runs the
    /// car's firmware and drives the model through this, not through receive()). From the
    /// first call on, this class's own watchdog is off: the chip's is the one that brakes.
    void drive(MotorMode mode, uint16_t pwm, uint16_t servo_us);
    /// One physics step of 1 / physics_rate seconds; runs the watchdog. A step that would
    /// take the body into a wall is undone: the car stops against it (a Collision).
    void step();
    /// The collisions since the last call (a car that stays against a wall counts once).
    std::vector<Collision> take_collisions();
    /// True while the body is against a wall (touched one within the last half second).
    bool against_wall() const { return model_.time() - last_contact_t_ <= 0.5; }
    /// Samples the sensors now and returns the state packet to send.
    StatePacket make_state_packet();

    /// Other cars' poses: their bodies become obstacles for the rangers.
    void set_other_cars(const std::vector<Pose>& poses);
    /// Distance (m) the ranger (0 front, 1 left, 2 right) would read now, without noise.
    double ultrasonic_range(size_t sensor) const;

    const VehicleModel& model() const { return model_; }
    const VehicleParameters& parameters() const { return p_; }
    const World& world() const { return world_; }
    FirmwareStats stats() const;
    bool watchdog_active() const { return watchdog_active_; }
    /// The motor command the controller holds now (the last valid command, or the watchdog's
    /// brake); the model feels it input_delay later.
    std::pair<MotorMode, uint16_t> motor_command() const { return motor_command_; }
    uint8_t vehicle_id() const { return vehicle_id_; }
    /// False from a state packet until a valid command for this car arrives.
    bool answered() const { return answered_; }
    /// A noisy copy of the true pose (observation_noise), for the indoor positioning system.
    Pose observed_pose();
    /// True when the next observation should be dropped (observation_dropout).
    bool drop_observation();

    /// The body outline of a car at `pose` as four segments.
    static std::vector<Segment> body_outline(const VehicleParameters& p, const Pose& pose);

private:
    void on_command(const CommandPacket& command);
    double noise(double sigma);

    VehicleParameters p_;
    World world_;
    VehicleModel model_;
    uint8_t vehicle_id_;
    std::mt19937 rng_;
    FrameDecoder decoder_;
    std::vector<Segment> obstacles_;
    FirmwareStats stats_;  // all but the decoder's errors, which stats() adds
    double last_command_t_ = 0;
    bool watchdog_active_ = false;
    bool bad_crc_ = false;
    bool wrong_vehicle_ = false;
    bool answered_ = true;
    bool driven_ = false;  ///< by drive(): no watchdog here
    uint32_t command_tick_ = 0;
    std::pair<MotorMode, uint16_t> motor_command_{MotorMode::brake, 0};
    double imu_yaw_ = 0;
    double last_contact_t_ = -1e9;
    std::vector<Collision> collisions_;
};

}  // namespace cpm::vehicle
