#pragma once
// The raw Fast DDS side of the comparisons: BenchPayload endpoints created with the plain
// Fast DDS API, with the QoS values cpm uses for the same options, on the participant (and
// so the transports) of a cpm::Participant.
#include <cpm/Participant.hpp>

#include "register_bench_types.hpp"

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>

#include <string>

namespace bench {

namespace fdds = eprosima::fastdds::dds;

struct RawEndpoints
{
    explicit RawEndpoints(cpm::Participant& participant);
    fdds::DataWriter* writer(const std::string& topic, bool keep_all, int depth);
    fdds::DataReader* reader(const std::string& topic, bool keep_all, int depth, fdds::DataReaderListener* listener);

    fdds::DomainParticipant* participant;
    fdds::TypeSupport type;
    fdds::Publisher* publisher;
    fdds::Subscriber* subscriber;
};

}  // namespace bench
