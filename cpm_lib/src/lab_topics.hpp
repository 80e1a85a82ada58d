#pragma once
// The lab's control topics (readyStatus, systemTrigger; cpm/topics.hpp), shared by Timer and
// TimeMaster.
#include <cpm/topics.hpp>

#include <cstdint>

namespace cpm::detail {

/// A SystemTrigger with this next_start stops every timer.
constexpr uint64_t kStopTrigger = UINT64_MAX;

/// Timer/TimeMaster control: transient-local (writers keep the latest sample per key), so
/// whoever matches late (a master started after its nodes, a node after the start) still sees
/// the current state. Readers keep a few and take the largest value: Fast DDS was seen
/// delivering an older sample of an instance after a newer one.
/// A transient-local reader does not match a volatile writer (cpm_lab's LCC writes its
/// SystemTrigger with a plain reliable writer): the control topics are read twice, by the
/// table's transient-local reader for what was sent before it matched and by this volatile one,
/// which matches every writer and so gets every sample sent after.
inline ReaderOptions live_reader_options(const TopicSpec& topic)
{
    ReaderOptions o = topic.reader;
    o.transient_local = false;
    return o;
}

}  // namespace cpm::detail
