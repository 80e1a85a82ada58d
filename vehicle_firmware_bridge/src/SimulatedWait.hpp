#pragma once
#include <cpm/Logging.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/vehicle/BridgeNode.hpp>

#include <chrono>
#include <thread>

namespace cpm::vehicle {

/// On the lab's simulated clock, bytes on a pty (or in simavr's uart) are still on their way
/// when a tick begins: checks `arrived` every 50 µs until it holds or `timeout` of real time
/// has passed (kSimulatedPacketWait unless said). Returns whether it holds.
template <class Arrived>
bool await_bytes(Arrived arrived, std::chrono::milliseconds timeout = kSimulatedPacketWait)
{
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    for (;;) {
        if (arrived()) return true;
        if (std::chrono::steady_clock::now() >= deadline) return false;
        std::this_thread::sleep_for(std::chrono::microseconds(50));
    }
}

/// A simulated controller's host did not answer its last state packet within kSimulatedPacketWait:
/// said once per silence (the controller then stops waiting for it).
inline void say_host_silent(unsigned vehicle_id)
{
    CPM_LOG_WARN("vehicle %u: no answer to the last state packet within %lld ms of real time at lab time %.3f s; not waiting "
                 "again until the host answers (the run will not repeat exactly)",
                 vehicle_id, (long long)kSimulatedPacketWait.count(), double(get_time_ns()) * 1e-9);
}

}  // namespace cpm::vehicle
