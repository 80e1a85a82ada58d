#pragma once
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

}  // namespace cpm::vehicle
