#include <cpm_test/RawWriter.hpp>

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/topic/TopicDataType.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>

#include <cstring>
#include <stdexcept>

namespace cpm_test {

namespace dds = eprosima::fastdds::dds;
using eprosima::fastrtps::rtps::SerializedPayload_t;

namespace {

struct Bytes
{
    std::vector<uint8_t> data;
};

class BytesType : public dds::TopicDataType
{
public:
    BytesType(const std::string& name, size_t key_offset) : key_offset_(key_offset)
    {
        setName(name.c_str());
        m_typeSize = 4096;
        m_isGetKeyDefined = true;
    }
    bool serialize(void* data, SerializedPayload_t* payload) override
    {
        const auto& b = static_cast<Bytes*>(data)->data;
        if (payload->max_size < b.size()) payload->reserve(static_cast<uint32_t>(b.size()));
        if (!b.empty()) std::memcpy(payload->data, b.data(), b.size());
        payload->length = static_cast<uint32_t>(b.size());
        return true;
    }
    bool deserialize(SerializedPayload_t* payload, void* data) override
    {
        static_cast<Bytes*>(data)->data.assign(payload->data, payload->data + payload->length);
        return true;
    }
    std::function<uint32_t()> getSerializedSizeProvider(void* data) override
    {
        return [data] { return static_cast<uint32_t>(static_cast<Bytes*>(data)->data.size()); };
    }
    void* createData() override { return new Bytes; }
    void deleteData(void* data) override { delete static_cast<Bytes*>(data); }
    bool getKey(void* data, eprosima::fastrtps::rtps::InstanceHandle_t* handle, bool) override
    {
        const auto& b = static_cast<Bytes*>(data)->data;
        for (size_t i = 0; i < 16; ++i) handle->value[i] = 0;
        if (b.size() > key_offset_) handle->value[0] = b[key_offset_];
        return true;
    }

private:
    size_t key_offset_;
};

}  // namespace

struct RawWriter::Impl
{
    dds::DomainParticipant* participant = nullptr;
    dds::Publisher* publisher = nullptr;
    dds::Topic* topic = nullptr;
    dds::DataWriter* writer = nullptr;
};

RawWriter::RawWriter(cpm::Participant& participant, const std::string& topic, const std::string& type_name, bool reliable,
                     size_t key_offset)
    : impl_(std::make_unique<Impl>())
{
    auto* p = participant.native();
    impl_->participant = p;
    // A participant that already knows the type (from a cpm reader or writer) keeps its own
    // registration: a test's raw writer then needs a participant of its own.
    if (!p->find_type(type_name).empty()) throw std::logic_error("RawWriter: the participant already has type " + type_name);
    dds::TypeSupport type(new BytesType(type_name, key_offset));
    type->auto_fill_type_information(false);
    type->auto_fill_type_object(false);
    if (type.register_type(p) != ReturnCode_t::RETCODE_OK) throw std::runtime_error("RawWriter: cannot register " + type_name);
    impl_->publisher = p->create_publisher(dds::PUBLISHER_QOS_DEFAULT);
    impl_->topic = p->create_topic(topic, type_name, dds::TOPIC_QOS_DEFAULT);
    dds::DataWriterQos qos = dds::DATAWRITER_QOS_DEFAULT;
    qos.reliability().kind = reliable ? dds::RELIABLE_RELIABILITY_QOS : dds::BEST_EFFORT_RELIABILITY_QOS;
    qos.data_sharing().off();
    impl_->writer = impl_->publisher ? impl_->publisher->create_datawriter(impl_->topic, qos) : nullptr;
    if (!impl_->topic || !impl_->writer) throw std::runtime_error("RawWriter: cannot create a writer on " + topic);
}

RawWriter::~RawWriter()
{
    if (impl_->writer) impl_->publisher->delete_datawriter(impl_->writer);
    if (impl_->publisher) impl_->participant->delete_publisher(impl_->publisher);
    if (impl_->topic) impl_->participant->delete_topic(impl_->topic);
}

bool RawWriter::write(const std::vector<uint8_t>& bytes)
{
    Bytes b{bytes};
    return impl_->writer->write(&b);
}

int RawWriter::matched() const
{
    eprosima::fastdds::dds::PublicationMatchedStatus status;
    impl_->writer->get_publication_matched_status(status);
    return status.current_count;
}

}  // namespace cpm_test
