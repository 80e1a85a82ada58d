#pragma once
#include <cpm/ReaderOptions.hpp>
#include <cpm/WriterOptions.hpp>

#include <fastdds/dds/publisher/qos/DataWriterQos.hpp>
#include <fastdds/dds/subscriber/qos/DataReaderQos.hpp>

#include <string>

namespace cpm::detail {

/// The DDS QoS for cpm's options, with the process's QoS overrides for the topic applied
/// (CPM_QOS_OVERRIDES, cpm/QosOverrides.hpp). Throws cpm::Error naming the topic and the bad value.
/// `keyed`: the type has a key (instances), which decides how keep_all's window is bounded.
/// `max_sample_bytes`: the type's largest serialized size; above kLargeSampleBytes the histories
/// allocate each sample at its real size instead of preallocating the largest (a CameraFrame
/// may be 6 MB; a reader preallocates 100 samples), unless data sharing needs them preallocated.
eprosima::fastdds::dds::DataWriterQos writer_qos(const WriterOptions& options, const std::string& topic, bool keyed,
                                                 uint32_t max_sample_bytes = 0);
eprosima::fastdds::dds::DataReaderQos reader_qos(const ReaderOptions& options, const std::string& topic,
                                                 uint32_t max_sample_bytes = 0);

inline constexpr uint32_t kLargeSampleBytes = 64 * 1024;

}  // namespace cpm::detail
