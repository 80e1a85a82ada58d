#include <cpm/detail/WriterCore.hpp>

#include "MatchCounter.hpp"
#include "ParticipantCore.hpp"
#include "QosFromOptions.hpp"
#include "log_internal.hpp"

#include <cpm/Error.hpp>

#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/DataWriterListener.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <fastdds/dds/topic/TopicDataType.hpp>

#include <algorithm>


namespace cpm::detail {

namespace dds = eprosima::fastdds::dds;

struct WriterCore::Impl : public dds::DataWriterListener
{
    Impl(std::shared_ptr<ParticipantCore> participant, const std::string& name, MakeTypeSupport make_type)
        : topic(std::move(participant), name, make_type, "Writer")
    {
    }
    TopicLease topic;
    dds::DataWriter* writer = nullptr;
    MatchCounter matched;
    bool plain = false;         // DDS lends samples of plain types only
    bool shared_loans = false;  // ... in shared memory, with data sharing

    void on_publication_matched(dds::DataWriter*, const dds::PublicationMatchedStatus& status) override
    {
        matched.set(status.current_count);
    }

    void on_offered_incompatible_qos(dds::DataWriter*, const dds::OfferedIncompatibleQosStatus& status) override
    {
        if (incompatible) incompatible->report(static_cast<int>(status.last_policy_id));
    }

    std::unique_ptr<IncompatibleQos> incompatible;
};

WriterCore::WriterCore(std::shared_ptr<ParticipantCore> participant, const std::string& topic,
                       MakeTypeSupport make_type, const WriterOptions& options)
{
    if (topic.empty()) throw Error("Writer: the topic name is empty");
    check_secured_endpoint(*participant, topic, true, options.data_sharing, "Writer");
    const std::unique_ptr<dds::TopicDataType> type(make_type());
    check_data_sharing(options.data_sharing, *type,
                       size_t(std::max(options.keep_all ? options.max_unacknowledged : options.history_depth, 1)), topic, "Writer");
    const dds::DataWriterQos qos = writer_qos(options, topic, type->m_isGetKeyDefined, type->m_typeSize);
    impl_ = std::make_unique<Impl>(std::move(participant), topic, make_type);
    impl_->plain = type->is_plain();
    impl_->shared_loans = options.data_sharing && impl_->plain;
    impl_->incompatible = std::make_unique<IncompatibleQos>(false, topic, options.reliable, options.transient_local);
    impl_->writer = impl_->topic.participant().publisher()->create_datawriter(
        impl_->topic.topic(), qos, impl_.get(),
        dds::StatusMask::publication_matched() << dds::StatusMask::offered_incompatible_qos());
    if (impl_->writer == nullptr) {
        throw Error("Writer on topic '" + topic + "': DDS refused to create the writer (inconsistent options?)");
    }
}

WriterCore::~WriterCore() { close(); }

WriterCore::WriterCore(WriterCore&& other) noexcept = default;

WriterCore& WriterCore::operator=(WriterCore&& other) noexcept
{
    if (this != &other) {
        close();
        impl_ = std::move(other.impl_);
    }
    return *this;
}

void WriterCore::close() noexcept
{
    if (!impl_) return;  // moved from
    impl_->writer->set_listener(nullptr);
    // Fast DDS 2.9 (fixed in 2.10.3) releases a writer's samples one by one without its lock
    // while deleting it: a heartbeat in between (a reliable reader had not acknowledged all)
    // reads released sequence numbers of 0 and counts gaps up to 2^64, holding the lock for
    // good (tests: Writer.AKeepAllWriterWith…, hung in its first round). An empty history
    // leaves the heartbeat nothing to count; what no reader acknowledged is lost either way.
    size_t removed = 0;
    (void)impl_->writer->clear_history(&removed);
    impl_->topic.participant().publisher()->delete_datawriter(impl_->writer);
    impl_.reset();
}

bool WriterCore::write(const void* sample)
{
    // Fast DDS takes a non-const pointer but only reads the sample.
    return impl_->writer->write(const_cast<void*>(sample));
}

void* WriterCore::loan() noexcept
{
    void* sample = nullptr;
    if (!impl_->plain) return nullptr;
    if (impl_->writer->loan_sample(sample) != ReturnCode_t::RETCODE_OK) return nullptr;
    return sample;
}

bool WriterCore::write_loan(void* sample) noexcept
{
    if (impl_->writer->write(sample)) return true;
    discard_loan(sample);  // a refused write leaves the sample on loan
    return false;
}

void WriterCore::discard_loan(void* sample) noexcept { (void)impl_->writer->discard_loan(sample); }

bool WriterCore::loans_are_shared() const noexcept { return impl_->shared_loans; }

size_t WriterCore::matched_subscriptions() const { return impl_->matched.get(); }

bool WriterCore::wait_for_matched(size_t n, std::chrono::nanoseconds timeout) const
{
    return impl_->matched.wait_for_at_least(n, timeout);
}

bool WriterCore::wait_for_acknowledgments(std::chrono::nanoseconds timeout)
{
    const auto ns = timeout.count();
    const eprosima::fastrtps::Duration_t max_wait(static_cast<int32_t>(ns / 1'000'000'000),
                                                  static_cast<uint32_t>(ns % 1'000'000'000));
    return impl_->writer->wait_for_acknowledgments(max_wait) == ReturnCode_t::RETCODE_OK;
}

const std::string& WriterCore::topic() const { return impl_->topic.name(); }

}  // namespace cpm::detail
