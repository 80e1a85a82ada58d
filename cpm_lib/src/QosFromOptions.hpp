#pragma once
#include <cpm/ReaderOptions.hpp>
#include <cpm/WriterOptions.hpp>

#include <fastdds/dds/publisher/qos/DataWriterQos.hpp>
#include <fastdds/dds/subscriber/qos/DataReaderQos.hpp>

#include <string>

namespace cpm::detail {

/// The DDS QoS for cpm's options. Throws cpm::Error naming the topic and the bad value.
/// `keyed`: the type has a key (instances), which decides how keep_all's window is bounded.
eprosima::fastdds::dds::DataWriterQos writer_qos(const WriterOptions& options, const std::string& topic, bool keyed);
eprosima::fastdds::dds::DataReaderQos reader_qos(const ReaderOptions& options, const std::string& topic);

}  // namespace cpm::detail
