#pragma once
#include <cpm/ReaderOptions.hpp>
#include <cpm/WriterOptions.hpp>

#include <fastdds/dds/publisher/qos/DataWriterQos.hpp>
#include <fastdds/dds/subscriber/qos/DataReaderQos.hpp>

#include <string>

namespace eprosima::fastdds::dds {
class TopicDataType;
}

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

/// Refuses data sharing where Fast DDS would quietly do without it, or where a writer's shared
/// pool (shared_pool_samples(history_samples) of the type's largest size) would exceed
/// kMaxSharedPoolBytes. A reader passes history_samples 0: it maps the writer's pool. Throws
/// cpm::Error naming the role, topic, type and reason.
void check_data_sharing(bool data_sharing, const eprosima::fastdds::dds::TopicDataType& type, size_t history_samples,
                        const std::string& topic, const char* role);
inline constexpr uint64_t kMaxSharedPoolBytes = 512ull << 20;

/// Fast DDS acknowledges a shared sample as soon as it is taken, and its writer may then reuse
/// the slot while the reader still reads it in place. So a reader with data sharing takes at most
/// this many samples at a time, and a writer's pool holds twice its history plus this many (+1):
/// in bench_large a reliable keep-all writer at 80,000+ samples/s then overwrote none (with one
/// history + 5 it overwrote 1–3 a run).
inline constexpr int kSharedTakeBatch = 4;
/// Samples in a data-sharing writer's pool for a history of `history_samples`.
inline size_t shared_pool_samples(size_t history_samples) { return 2 * history_samples + kSharedTakeBatch + 1; }

}  // namespace cpm::detail
