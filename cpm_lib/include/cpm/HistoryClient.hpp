#pragma once
// cpm::HistoryClient — asks the lab's history service (cpm_history) what an object was at a
// time in the recent past, by commit time (when the service received it) or by data time
// (create_stamp). Typed calls decode the stored payload as T; untyped calls return the reply
// with the payload bytes.
//
//   cpm::HistoryClient history;
//   auto r = history.at<VehicleState>("vehicleState", 3, t);   // r.ok(), r.status, r.sample
//
// The client asks a HistoryBackend: by default the lab's history service over DDS; any other
// backend that answers the same HistoryRequests (a cpm::rtdb::Store in this process, a
// recording) serves the same calls.
#include <cpm/Error.hpp>
#include <cpm/HistoryVocabulary.hpp>
#include <cpm/Participant.hpp>
#include <cpm/TopicType.hpp>

#include <HistoryReply.h>
#include <HistoryRequest.h>
#include <cpm_topic_types.hpp>

#include <chrono>
#include <cstring>
#include <memory>
#include <string>
#include <type_traits>
#include <vector>

namespace cpm {

template <class T>
struct [[nodiscard]] HistoryResult
{
    history::Status status = history::Status::error;
    std::string error;  ///< why, when the request was refused
    uint64_t commit_ns = 0, data_ns = 0, valid_after_ns = 0, source_ns = 0;
    T sample{};
    bool ok() const { return status == history::Status::ok; }
};

/// A range's answer, whole: its samples and whether they are all the span asked for.
template <class T>
struct [[nodiscard]] HistoryRange
{
    /// ok; partial: the span reached back past the window, the samples are what is held;
    /// not_found, evicted, not_yet, unknown_object, error (then no samples).
    history::Status status = history::Status::error;
    std::string error;
    std::vector<HistoryResult<T>> samples;  ///< oldest first
    bool truncated = false;                 ///< more matched than the limit: the oldest are here
    uint64_t lost = 0;                      ///< samples never received between the first and the last
    bool complete() const { return status == history::Status::ok && !truncated; }
};

using HistoryBy = history::By;

/// What answers a HistoryClient's requests.
class HistoryBackend
{
public:
    virtual ~HistoryBackend() = default;
    /// Answers one request, waiting up to its timeout_ns for the kinds that wait. A malformed
    /// request is answered (status error, with the reason); throws cpm::Error only when no
    /// answer can be had (no service, no reply in time).
    virtual HistoryReply request(const HistoryRequest& rq) = 0;
};

/// The lab's history service (cpm_history) over DDS. reply_timeout: how long to wait for the
/// service beyond a request's own timeout.
std::unique_ptr<HistoryBackend> history_service_backend(Participant& participant = Participant::default_participant(),
                                                        std::chrono::milliseconds reply_timeout = std::chrono::milliseconds(3000));

/// How often an object has been updated lately, as `cpm dump` shows it: the samples it holds
/// over the time they can span — from the later of its creation and its history interval
/// before now (or before its deletion) until then; from its oldest sample held where that lies
/// further back (a recording keeps every sample). 0 for a process, an object holding nothing,
/// or one whose samples span less than a second, too short to tell a rate (unlike
/// 1 / avg_cycle_s, two log lines a moment apart do not make 10 kHz).
double update_rate_hz(const HistoryObject& o, uint64_t now_ns);

class HistoryClient
{
public:
    /// Asks the lab's history service. reply_timeout: how long to wait for the service beyond a
    /// request's own timeout.
    explicit HistoryClient(Participant& participant = Participant::default_participant(),
                           std::chrono::milliseconds reply_timeout = std::chrono::milliseconds(3000));
    /// Asks another backend.
    explicit HistoryClient(std::unique_ptr<HistoryBackend> backend);
    /// Answers from a finished run's recording (recording.db) the calls the live service
    /// answers, read into memory once. Defined in the cpm::rtdb library (link it). Throws
    /// cpm::Error naming the file when it is not a recording; a damaged one answers up to the
    /// damage.
    static HistoryClient open_recording(const std::string& path);
    ~HistoryClient();
    HistoryClient(HistoryClient&&) noexcept;
    HistoryClient& operator=(HistoryClient&&) noexcept;

    /// Sends a request and waits for its reply. Throws cpm::Error when no answer can be had.
    HistoryReply request(const HistoryRequest& rq);

    // Untyped: the reply, payloads as bytes.
    HistoryReply latest(const std::string& topic, const std::string& key = "");
    HistoryReply at(const std::string& topic, const std::string& key, uint64_t t, HistoryBy by = HistoryBy::commit);

    // Typed: the payload decoded as T (a cpm type, or one registered with CPM_REGISTER_TYPE).
    template <class T, class Key>
    HistoryResult<T> latest(const std::string& topic, const Key& key)
    {
        return decoded<T>(request(make(history::Kind::latest, topic, key_text(key))));
    }
    template <class T, class Key>
    HistoryResult<T> at(const std::string& topic, const Key& key, uint64_t t, HistoryBy by = HistoryBy::commit)
    {
        return decoded<T>(request(make(history::Kind::at, topic, key_text(key), t, by)));
    }
    template <class T, class Key>
    HistoryResult<T> older(const std::string& topic, const Key& key, uint64_t t, HistoryBy by = HistoryBy::commit)
    {
        return decoded<T>(request(make(history::Kind::older, topic, key_text(key), t, by)));
    }
    template <class T, class Key>
    HistoryResult<T> younger(const std::string& topic, const Key& key, uint64_t t, HistoryBy by = HistoryBy::commit)
    {
        return decoded<T>(request(make(history::Kind::younger, topic, key_text(key), t, by)));
    }
    /// The newest sample committed after `after`, waiting up to `timeout`.
    template <class T, class Key>
    HistoryResult<T> wait_next(const std::string& topic, const Key& key, uint64_t after, std::chrono::nanoseconds timeout)
    {
        auto rq = make(history::Kind::wait_next, topic, key_text(key), after);
        rq.timeout_ns(static_cast<uint64_t>(timeout.count()));
        return decoded<T>(request(rq));
    }
    /// Samples with time in [t0, t1), oldest first, with whether that is the whole span
    /// (partial: part of it was evicted; truncated: cut at the limit).
    template <class T, class Key>
    HistoryRange<T> range_of(const std::string& topic, const Key& key, uint64_t t0, uint64_t t1, HistoryBy by = HistoryBy::commit,
                             uint32_t limit = 1000)
    {
        auto rq = make(history::Kind::range, topic, key_text(key), t0, by);
        rq.t1(t1);
        rq.limit(limit);
        const auto reply = request(rq);
        HistoryRange<T> out;
        out.status = status_of(reply.status(), out.error);
        if (out.error.empty()) out.error = reply.error();
        out.truncated = reply.truncated();
        out.lost = reply.lost();
        for (const auto& s : reply.samples()) out.samples.push_back(decode<T>(s, reply));
        return out;
    }
    /// The samples of range_of alone (whether the span was whole is not told: use range_of).
    template <class T, class Key>
    std::vector<HistoryResult<T>> range(const std::string& topic, const Key& key, uint64_t t0, uint64_t t1,
                                        HistoryBy by = HistoryBy::commit, uint32_t limit = 1000)
    {
        return range_of<T>(topic, key, t0, t1, by, limit).samples;
    }

    /// Decodes a stored payload (CDR encapsulation included) as T.
    template <class T>
    static bool decode_payload(const std::vector<uint8_t>& bytes, T& out)
    {
        return TopicType<T>::decode(bytes, out);
    }

    static HistoryRequest make(history::Kind kind, const std::string& topic, const std::string& key, uint64_t t0 = 0,
                               HistoryBy by = HistoryBy::commit);

private:
    template <class K>
    static std::string key_text(const K& key)
    {
        if constexpr (std::is_arithmetic_v<K>) return std::to_string(static_cast<long long>(key));
        else return std::string(key);
    }
    template <class T>
    static HistoryResult<T> decode(const HistorySample& s, const HistoryReply& reply)
    {
        HistoryResult<T> r;
        r.status = status_of(s.status().empty() ? reply.status() : s.status(), r.error);
        if (r.error.empty()) r.error = reply.error();
        r.commit_ns = s.commit_ns();
        r.data_ns = s.data_ns();
        r.valid_after_ns = s.valid_after_ns();
        r.source_ns = s.source_ns();
        if (!decode_payload(s.payload(), r.sample)) {
            r.status = history::Status::error;
            r.error = "the stored payload does not decode as the type asked for";
        }
        return r;
    }
    template <class T>
    static HistoryResult<T> decoded(const HistoryReply& reply)
    {
        if (reply.samples().empty()) {
            HistoryResult<T> r;
            r.status = status_of(reply.status(), r.error);
            if (r.error.empty()) r.error = reply.error();
            return r;
        }
        return decode<T>(reply.samples().front(), reply);
    }

    /// The wire's status as the enum; a spelling this build does not know is an error, named in `error`.
    static history::Status status_of(const std::string& wire, std::string& error);

    std::unique_ptr<HistoryBackend> backend_;
};

}  // namespace cpm
