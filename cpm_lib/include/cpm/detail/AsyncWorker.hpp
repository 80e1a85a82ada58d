#pragma once
#include <atomic>
#include <functional>
#include <memory>
#include <thread>

namespace cpm::detail {
class ReaderCore;

/// The thread behind AsyncReader: waits for data on a ReaderCore and runs `on_data` on its
/// own thread, never a DDS thread and never under a DDS lock. An exception thrown by
/// `on_data` is logged to stderr and the worker keeps going.
class AsyncWorker
{
public:
    AsyncWorker(ReaderCore& core, std::function<void()> on_data);
    /// stop(); destroyed from inside its own callback, the thread ends when that returns.
    ~AsyncWorker();
    AsyncWorker(const AsyncWorker&) = delete;
    AsyncWorker& operator=(const AsyncWorker&) = delete;

    /// Stops the thread and joins it (after a running callback returns). Safe to call
    /// more than once and from inside the callback (then the thread ends after it).
    void stop();

private:
    // What the thread touches after a callback returns: it outlives a worker destroyed
    // from inside its own callback.
    struct State
    {
        std::atomic<bool> stopping{false};
        std::function<void()> on_data;
    };
    static void run(State& state, ReaderCore& core);
    ReaderCore& core_;
    std::shared_ptr<State> state_;
    std::thread thread_;
};

}  // namespace cpm::detail
