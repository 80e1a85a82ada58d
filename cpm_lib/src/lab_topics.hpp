#pragma once
// The lab's control topics, shared by Timer and TimeMaster.
#include <cpm/ReaderOptions.hpp>
#include <cpm/WriterOptions.hpp>

#include <cstdint>

namespace cpm::detail {

constexpr const char* kReadyStatusTopic = "readyStatus";
constexpr const char* kSystemTriggerTopic = "systemTrigger";
/// A SystemTrigger with this next_start stops every timer.
constexpr uint64_t kStopTrigger = UINT64_MAX;

/// Reliable and transient-local (writers keep the latest sample per key): whoever matches late
/// (a master started after its nodes, a node after the start) still sees the current state.
/// Readers keep a few, and readers take the largest value: Fast DDS was seen delivering an
/// older sample of an instance after a newer one.
inline WriterOptions lab_control_writer_options()
{
    WriterOptions o;
    o.reliable = true;
    o.transient_local = true;
    o.history_depth = 1;
    return o;
}
inline ReaderOptions lab_control_reader_options()
{
    ReaderOptions o;
    o.reliable = true;
    o.transient_local = true;
    o.history_depth = 64;
    return o;
}

}  // namespace cpm::detail
