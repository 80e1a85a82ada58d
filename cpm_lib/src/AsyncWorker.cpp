#include <cpm/detail/AsyncWorker.hpp>

#include "log_internal.hpp"
#include "realtime_internal.hpp"

#include <cpm/detail/ReaderCore.hpp>

namespace cpm::detail {

AsyncWorker::AsyncWorker(ReaderCore& core, std::function<void()> on_data)
    : core_(core), state_(std::make_shared<State>())
{
    state_->on_data = std::move(on_data);
    thread_ = std::thread([state = state_, &core] { run(*state, core); });
}

AsyncWorker::~AsyncWorker()
{
    stop();
    if (thread_.joinable()) thread_.detach();  // only when destroyed from inside the callback
}

void AsyncWorker::stop()
{
    state_->stopping = true;
    core_.interrupt();
    if (thread_.joinable() && thread_.get_id() != std::this_thread::get_id()) thread_.join();
}

void AsyncWorker::run(State& state, ReaderCore& core)
{
    run_at_normal_priority();  // a reader made on a real-time loop calls back at normal priority
    while (!state.stopping) {
        if (!core.wait_for_data(std::chrono::seconds(1))) continue;
        if (state.stopping) break;
        try {
            state.on_data();
        } catch (const std::exception& e) {
            log_error("AsyncReader on topic '" + core.topic() + "': callback threw: " + e.what());
        } catch (...) {
            log_error("AsyncReader on topic '" + core.topic() + "': callback threw a non-standard exception");
        }
    }
}

}  // namespace cpm::detail
