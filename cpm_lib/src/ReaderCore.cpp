#include <cpm/detail/ReaderCore.hpp>

#include "MatchCounter.hpp"
#include "ParticipantCore.hpp"
#include "QosFromOptions.hpp"
#include "log_internal.hpp"

#include <cpm/Error.hpp>
#include <cpm/LogThrottle.hpp>
#include <cpm/get_time_ns.hpp>

#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/core/LoanableCollection.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <fastdds/dds/topic/TopicDataType.hpp>

#include <condition_variable>
#include <set>
#include <mutex>

namespace cpm::detail {

namespace dds = eprosima::fastdds::dds;

namespace {

// A sequence that only ever holds samples loaned by the reader: take() then hands over a
// whole batch under one lock of the reader's history, instead of one lock per sample.
class LoanedSamples : public dds::LoanableCollection
{
public:
    void* at(size_type i) const { return buffer()[i]; }

protected:
    void resize(size_type) override {}  // never owns elements: loans only
};

}  // namespace

struct ReaderCore::Impl : public dds::DataReaderListener
{
    Impl(std::shared_ptr<ParticipantCore> participant, const std::string& name, MakeTypeSupport make_type,
         const char* role, Sink sink, BatchEnd batch_end)
        : topic(std::move(participant), name, make_type, role), on_arrival(std::move(sink)),
          after_arrivals(std::move(batch_end))
    {
    }
    TopicLease topic;
    dds::DataReader* reader = nullptr;
    Sink on_arrival;
    BatchEnd after_arrivals;


    // Fast DDS calls the listener with the reader's history locked, so nobody may call into
    // DDS while holding wait_mutex: the listener only raises `pending` under it.
    std::mutex wait_mutex;
    std::condition_variable data_ready;
    bool pending = false;
    bool interrupted = false;

    MatchCounter matched;

    std::mutex listener_mutex;  // held while a listener callback runs
    bool closing = false;
    dds::SampleInfoSeq listener_infos;  // under listener_mutex: no allocation per arrival
    int32_t max_per_take = dds::LENGTH_UNLIMITED;  // kSharedTakeBatch with data sharing
    bool loans_are_shared = false;  // data sharing with a plain type: loans lie in the writer's pool
    std::mutex overwritten_mutex;
    LogThrottle overwritten_log;  // under overwritten_mutex

    void report_overwritten()
    {
        std::lock_guard<std::mutex> lock(overwritten_mutex);
        uint64_t held = 0;
        if (!overwritten_log.allow(get_time_ns(), held)) return;
        log_error("reader on topic '" + topic.name() + "': a shared sample was overwritten by its writer while it was read (" +
                  std::to_string(held) + " more since the last report); raise the writer's history_depth or read faster");
    }
    // The core whose listener callback this thread is running (stop_arrivals from inside).
    static thread_local const Impl* running_here;

    // Samples are passed in arrival order; the sink may move from them (a loaned sample is
    // deserialized anew before Fast DDS lends it again).
    size_t drain_from(dds::DataReader* from, const Sink& sink)
    {
        dds::SampleInfoSeq infos;
        return drain_from(from, sink, infos);
    }
    // `infos` is reused from call to call where one thread at a time drains (the listener).
    size_t drain_from(dds::DataReader* from, const Sink& sink, dds::SampleInfoSeq& infos)
    {
        size_t n = 0;
        LoanedSamples samples;
        while (from->take(samples, infos, max_per_take) == ReturnCode_t::RETCODE_OK) {
            for (LoanedSamples::size_type i = 0; i < samples.length(); ++i) {
                if (!infos[i].valid_data) continue;  // disposals and unregistrations carry no data
                try {
                    sink(samples.at(i));
                } catch (const std::exception& e) {
                    log_error("reader on topic '" + topic.name() + "': dropped a sample: " + e.what());
                }
                // Read in place from data sharing's pool (a plain type), a sample can be
                // overwritten meanwhile by a writer that needed its slot back. (Fast DDS's check
                // reads the bytes before the sample: only a shared loan has them.)
                if (loans_are_shared && !from->is_sample_valid(samples.at(i), &infos[i])) report_overwritten();
                ++n;
            }
            from->return_loan(samples, infos);
        }
        return n;
    }

    void on_data_available(dds::DataReader* from) override
    {
        std::lock_guard<std::mutex> lock(listener_mutex);
        if (closing) return;
        if (on_arrival) {
            // A callback may write to a reader of this process, which Fast DDS then calls here
            // on this very thread: the outer core is restored afterwards.
            const Impl* outer = running_here;
            running_here = this;
            drain_from(from, on_arrival, listener_infos);
            if (after_arrivals && !closing) {
                try {
                    after_arrivals();
                } catch (const std::exception& e) {
                    log_error("reader on topic '" + topic.name() + "': the callback threw: " + e.what());
                } catch (...) {
                    log_error("reader on topic '" + topic.name() + "': the callback threw a non-standard exception");
                }
            }
            running_here = outer;
            return;
        }
        {
            std::lock_guard<std::mutex> wait_lock(wait_mutex);
            pending = true;
        }
        data_ready.notify_all();
    }

    void on_subscription_matched(dds::DataReader*, const dds::SubscriptionMatchedStatus& status) override
    {
        matched.set(status.current_count);
    }

    void on_requested_incompatible_qos(dds::DataReader*, const dds::RequestedIncompatibleQosStatus& status) override
    {
        if (incompatible) incompatible->report(static_cast<int>(status.last_policy_id));
    }

    std::unique_ptr<IncompatibleQos> incompatible;
};

thread_local const ReaderCore::Impl* ReaderCore::Impl::running_here = nullptr;

ReaderCore::ReaderCore(std::shared_ptr<ParticipantCore> participant, const std::string& topic,
                       MakeTypeSupport make_type, const ReaderOptions& options, const char* role, Sink on_arrival,
                       BatchEnd after_arrivals)
{
    if (topic.empty()) throw Error(std::string(role) + ": the topic name is empty");
    if (options.dds_thread_callback && !after_arrivals) {
        throw Error(std::string(role) + " on topic '" + topic + "': option dds_thread_callback cannot be used with a " + role +
                    ": it is read by the caller's thread (take/get_sample/wait_for_...), and only an AsyncReader's "
                    "callback can run on the DDS thread");
    }
    check_secured_endpoint(*participant, topic, false, options.data_sharing, role);
    const std::unique_ptr<dds::TopicDataType> type(make_type());
    check_data_sharing(options.data_sharing, *type, 0, topic, role);
    const dds::DataReaderQos qos = reader_qos(options, topic, type->m_typeSize);
    impl_ = std::make_unique<Impl>(std::move(participant), topic, make_type, role, std::move(on_arrival),
                                   std::move(after_arrivals));
    impl_->incompatible = std::make_unique<IncompatibleQos>(true, topic, options.reliable, options.transient_local);
    if (options.data_sharing) impl_->max_per_take = kSharedTakeBatch;
    impl_->loans_are_shared = options.data_sharing && type->is_plain();
    impl_->reader = impl_->topic.participant().subscriber()->create_datareader(
        impl_->topic.topic(), qos, impl_.get(),
        dds::StatusMask::data_available() << dds::StatusMask::subscription_matched()
                                          << dds::StatusMask::requested_incompatible_qos());
    if (impl_->reader == nullptr) {
        throw Error(std::string(role) + " on topic '" + topic + "': DDS refused to create the reader "
                    "(inconsistent options?)");
    }
}

ReaderCore::~ReaderCore() { close(); }

ReaderCore::ReaderCore(ReaderCore&& other) noexcept = default;

ReaderCore& ReaderCore::operator=(ReaderCore&& other) noexcept
{
    if (this != &other) {
        close();
        impl_ = std::move(other.impl_);
    }
    return *this;
}

void ReaderCore::stop_arrivals()
{
    if (Impl::running_here == impl_.get()) {  // inside its own callback: the lock is ours already
        impl_->closing = true;
        return;
    }
    std::lock_guard<std::mutex> lock(impl_->listener_mutex);  // waits for a running callback
    impl_->closing = true;
}

void ReaderCore::close() noexcept
{
    if (!impl_) return;  // moved from
    stop_arrivals();
    interrupt();
    impl_->reader->set_listener(nullptr);
    impl_->topic.participant().subscriber()->delete_datareader(impl_->reader);
    impl_.reset();
}

size_t ReaderCore::drain(const Sink& sink) { return impl_->drain_from(impl_->reader, sink); }

bool ReaderCore::wait_for_data(std::chrono::nanoseconds timeout)
{
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (true) {
        {
            std::lock_guard<std::mutex> lock(impl_->wait_mutex);
            if (impl_->interrupted) return false;
        }
        if (impl_->reader->get_unread_count() > 0) return true;  // no lock of ours held
        // Data arriving from here on raises `pending`, so no wake-up is lost.
        std::unique_lock<std::mutex> lock(impl_->wait_mutex);
        if (!impl_->data_ready.wait_until(lock, deadline, [&] { return impl_->interrupted || impl_->pending; })) {
            return false;
        }
        if (impl_->interrupted) return false;
        impl_->pending = false;
    }
}

void ReaderCore::interrupt()
{
    {
        std::lock_guard<std::mutex> lock(impl_->wait_mutex);
        impl_->interrupted = true;
    }
    impl_->data_ready.notify_all();
}

size_t ReaderCore::matched_publications() const { return impl_->matched.get(); }

bool ReaderCore::wait_for_matched(size_t n, std::chrono::nanoseconds timeout) const
{
    return impl_->matched.wait_for_at_least(n, timeout);
}

const std::string& ReaderCore::topic() const { return impl_->topic.name(); }

}  // namespace cpm::detail
