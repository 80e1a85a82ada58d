#include "raw_fastdds.hpp"

#include "bench_common.hpp"

#include <cstdlib>


namespace bench {

RawEndpoints::RawEndpoints(cpm::Participant& p)
    : participant(p.native()), type(new BenchPayloadPubSubType())
{
    type.register_type(participant);
    publisher = participant->create_publisher(fdds::PUBLISHER_QOS_DEFAULT);
    subscriber = participant->create_subscriber(fdds::SUBSCRIBER_QOS_DEFAULT);
}

namespace {
template <class Qos>
void same_as_cpm(Qos& qos, bool keep_all, int depth)
{
    qos.reliability().kind = fdds::RELIABLE_RELIABILITY_QOS;
    qos.durability().kind = fdds::VOLATILE_DURABILITY_QOS;
    qos.history().kind = keep_all ? fdds::KEEP_ALL_HISTORY_QOS : fdds::KEEP_LAST_HISTORY_QOS;
    qos.history().depth = keep_all ? 1 : depth;
    qos.resource_limits().max_instances = 0;
    qos.resource_limits().max_samples = 0;
    qos.resource_limits().max_samples_per_instance = keep_all ? 0 : depth;
    if (bench::data_sharing()) {
        qos.data_sharing().automatic();
    } else {
        qos.data_sharing().off();
    }
}
}  // namespace

namespace {
/// BENCH_FASTDDS_MODE: more of Fast DDS 2.9's throughput settings for the raw endpoints, to
/// try beside cpm's (bench/README.md has the figures), comma-separated: async (asynchronous
/// publishing, default flow controller), noack (positive acknowledgements off, samples kept 100 ms).
bool mode_has(const char* what)
{
    const char* mode = std::getenv("BENCH_FASTDDS_MODE");
    return mode && std::string(mode).find(what) != std::string::npos;
}
}  // namespace

fdds::DataWriter* RawEndpoints::writer(const std::string& topic, bool keep_all, int depth)
{
    auto* t = participant->create_topic(topic, type.get_type_name(), fdds::TOPIC_QOS_DEFAULT);
    fdds::DataWriterQos qos = fdds::DATAWRITER_QOS_DEFAULT;
    same_as_cpm(qos, keep_all, depth);
    qos.reliable_writer_qos().times.heartbeatPeriod = {0, 100'000'000};
    if (keep_all) {  // cpm's max_unacknowledged window for an unkeyed type
        qos.resource_limits().max_instances = 1;
        qos.resource_limits().max_samples_per_instance = 1024;
        qos.resource_limits().max_samples = 1024;
    }
    qos.reliability().max_blocking_time = {0, 100'000'000};
    if (mode_has("async")) qos.publish_mode().kind = fdds::ASYNCHRONOUS_PUBLISH_MODE;
    if (mode_has("noack")) {
        qos.reliable_writer_qos().disable_positive_acks.enabled = true;
        qos.reliable_writer_qos().disable_positive_acks.duration = {0, 100'000'000};
    }
    return publisher->create_datawriter(t, qos);
}

fdds::DataReader* RawEndpoints::reader(const std::string& topic, bool keep_all, int depth,
                                       fdds::DataReaderListener* listener)
{
    auto* t = participant->create_topic(topic, type.get_type_name(), fdds::TOPIC_QOS_DEFAULT);
    fdds::DataReaderQos qos = fdds::DATAREADER_QOS_DEFAULT;
    same_as_cpm(qos, keep_all, depth);
    qos.reliable_reader_qos().times.heartbeatResponseDelay = {0, 0};  // as cpm's readers
    if (mode_has("noack")) qos.reliable_reader_qos().disable_positive_ACKs.enabled = true;
    return subscriber->create_datareader(t, qos, listener,
                                         listener ? fdds::StatusMask::data_available() : fdds::StatusMask::none());
}

}  // namespace bench
