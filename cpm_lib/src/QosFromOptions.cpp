#include "QosFromOptions.hpp"

#include <algorithm>

#include <cpm/Error.hpp>
#include <cpm/QosOverrides.hpp>

#include <fastdds/dds/topic/TopicDataType.hpp>

namespace cpm::detail {

namespace dds = eprosima::fastdds::dds;

namespace {

// The parts readers and writers share: reliability, durability, history and limits.
// Instances a bounded keep-all writer serves: every possible vehicle_id.
constexpr int32_t kKeepAllMaxInstances = 256;

// keep_all_limit: samples per instance a keep-all history holds (0: no limit); keyed: whether
// the type has instances (an unkeyed topic has one, and only max_samples applies to it).
template <class Qos>
void apply_common(Qos& qos, bool reliable, bool transient_local, bool keep_all, int depth, int keep_all_limit,
                  bool keyed, bool data_sharing, uint32_t max_sample_bytes, const std::string& topic, const char* role)
{
    if (!keep_all && depth < 1) {
        throw Error(std::string(role) + " on topic '" + topic + "': history_depth = " + std::to_string(depth) +
                    " must be at least 1 (or set keep_all)");
    }
    qos.reliability().kind = reliable ? dds::RELIABLE_RELIABILITY_QOS : dds::BEST_EFFORT_RELIABILITY_QOS;
    qos.durability().kind = transient_local ? dds::TRANSIENT_LOCAL_DURABILITY_QOS : dds::VOLATILE_DURABILITY_QOS;
    qos.history().kind = keep_all ? dds::KEEP_ALL_HISTORY_QOS : dds::KEEP_LAST_HISTORY_QOS;
    qos.history().depth = keep_all ? 1 : depth;
    // Fast DDS's default allows only 10 instances (vehicles) per reader and writer. 0 means
    // "no limit" to Fast DDS 2.9's histories; LENGTH_UNLIMITED (-1) makes every write fail.
    auto& limits = qos.resource_limits();
    if (keep_all && keep_all_limit > 0) {
        // A bounded window; Fast DDS then wants every limit finite (max_samples = product).
        limits.max_instances = keyed ? kKeepAllMaxInstances : 1;
        limits.max_samples_per_instance = keep_all_limit;
        limits.max_samples = limits.max_instances * keep_all_limit;
    } else {
        limits.max_instances = 0;
        limits.max_samples = 0;
        limits.max_samples_per_instance = keep_all ? 0 : depth;
    }
    if (data_sharing) {
        qos.data_sharing().automatic();
        // Slots beyond the history (see kSharedTakeBatch).
        const size_t history_samples = size_t(keep_all ? std::max(keep_all_limit, 1) : depth);
        limits.extra_samples = int32_t(shared_pool_samples(history_samples) - history_samples);
    } else {
        qos.data_sharing().off();  // shared-memory transport instead: faster for small samples
        if (max_sample_bytes > kLargeSampleBytes) {
            qos.endpoint().history_memory_policy = eprosima::fastrtps::rtps::DYNAMIC_REUSABLE_MEMORY_MODE;
        }
    }
}

}  // namespace

void check_data_sharing(bool data_sharing, const dds::TopicDataType& type, size_t history_samples, const std::string& topic,
                        const char* role)
{
    if (!data_sharing) return;
    const std::string where = std::string(role) + " on topic '" + topic + "': data_sharing with type " + type.getName();
    if (type.m_isGetKeyDefined) {
        throw Error(where + ": the type has a key (@key), and Fast DDS shares only unkeyed types; leave data_sharing off "
                    "(the shared-memory transport still carries it) or publish an unkeyed type");
    }
    if (!type.is_bounded()) {
        throw Error(where + ": the type is not bounded (an unbounded string or sequence), and Fast DDS shares only "
                    "bounded types; bound every string and sequence in the IDL, or leave data_sharing off");
    }
    const size_t pool_samples = history_samples == 0 ? 0 : shared_pool_samples(history_samples);
    const uint64_t pool_bytes = uint64_t(pool_samples) * type.m_typeSize;
    if (pool_bytes > kMaxSharedPoolBytes) {
        throw Error(where + ": the shared pool would hold " + std::to_string(pool_samples) + " samples of up to " +
                    std::to_string(type.m_typeSize) + " bytes (" + std::to_string(pool_bytes >> 20) + " MiB, more than " +
                    std::to_string(kMaxSharedPoolBytes >> 20) + " MiB: twice the history, and a few more); lower history_depth "
                    "or max_unacknowledged");
    }
}

dds::DataWriterQos writer_qos(const WriterOptions& given, const std::string& topic, bool keyed, uint32_t max_sample_bytes)
{
    const WriterOptions options = overridden(given, topic, qos_overrides());
    dds::DataWriterQos qos = dds::DATAWRITER_QOS_DEFAULT;
    if (options.keep_all && options.max_unacknowledged < 1) {
        throw Error("Writer on topic '" + topic + "': max_unacknowledged = " +
                    std::to_string(options.max_unacknowledged) + " must be at least 1");
    }
    // An unlimited keep-all writer slows down quadratically in Fast DDS 2.9 (its per-reader
    // list of changes grows one element at a time); a bounded window also bounds memory.
    apply_common(qos, options.reliable, options.transient_local, options.keep_all, options.history_depth,
                 options.max_unacknowledged, keyed, options.data_sharing, max_sample_bytes, topic, "Writer");
    // Fast DDS's default heartbeat (3 s) delays recovery of a lost sample by seconds.
    qos.reliable_writer_qos().times.heartbeatPeriod = {0, 100'000'000};
    qos.reliability().max_blocking_time = {0, 100'000'000};
    return qos;
}

dds::DataReaderQos reader_qos(const ReaderOptions& given, const std::string& topic, uint32_t max_sample_bytes)
{
    const ReaderOptions options = overridden(given, topic, qos_overrides());
    dds::DataReaderQos qos = dds::DATAREADER_QOS_DEFAULT;
    // A keep-all reader keeps what was not taken yet, without limit.
    apply_common(qos, options.reliable, options.transient_local, options.keep_all, options.history_depth, 0,
                 true, options.data_sharing, max_sample_bytes, topic, "Reader");
    // Fast DDS 2.9 waits 5 ms before answering a heartbeat: a keep-all writer whose window is
    // full waits that long for the acknowledgement that frees it (bench/throughput: +12 % raw).
    // A topic whose writers keep the last sample only may ask for a wait instead.
    const auto after_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(options.acknowledge_after).count();
    qos.reliable_reader_qos().times.heartbeatResponseDelay = {int32_t(after_ns / 1'000'000'000), uint32_t(after_ns % 1'000'000'000)};
    return qos;
}

}  // namespace cpm::detail
