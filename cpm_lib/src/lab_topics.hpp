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

/// Reliable options (WriterOptions or ReaderOptions) with a history depth, optionally
/// transient-local (cpm's own services).
template <class Options>
Options reliable_options(int depth, bool transient_local)
{
    Options o;
    o.reliable = true;
    o.transient_local = transient_local;
    o.history_depth = depth;
    return o;
}
inline WriterOptions reliable_writer_options(int depth, bool transient_local)
{
    return reliable_options<WriterOptions>(depth, transient_local);
}
inline ReaderOptions reliable_reader_options(int depth, bool transient_local)
{
    return reliable_options<ReaderOptions>(depth, transient_local);
}

/// Timer/TimeMaster control: transient-local (writers keep the latest sample per key), so
/// whoever matches late (a master started after its nodes, a node after the start) still sees
/// the current state. Readers keep a few and take the largest value: Fast DDS was seen
/// delivering an older sample of an instance after a newer one.
/// A transient-local reader does not match a volatile writer (cpm_lab's LCC writes its
/// SystemTrigger with a plain reliable writer): the control topics are read twice, by a
/// transient-local reader for what was sent before it matched and by a volatile one that
/// matches every writer and so gets every sample sent after.
inline WriterOptions lab_control_writer_options() { return reliable_writer_options(1, true); }
inline ReaderOptions lab_control_reader_options() { return reliable_reader_options(64, true); }
inline ReaderOptions lab_control_live_reader_options() { return reliable_reader_options(64, false); }

}  // namespace cpm::detail
