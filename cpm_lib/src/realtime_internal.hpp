#pragma once
#include <cpm/Realtime.hpp>

#include <string>

namespace cpm::detail {

/// cpm::init's part of --realtime: locks the memory and checks the priorities; says what is
/// missing once (Realtime::on), or throws it (Realtime::required).
void start_realtime(Realtime mode, const std::string& node_id);

/// A thread inherits its creator's scheduling: one cpm starts for its own work (a reader's
/// callbacks, the log) from a real-time thread calls this first, to run at normal priority.
void run_at_normal_priority();

}  // namespace cpm::detail
