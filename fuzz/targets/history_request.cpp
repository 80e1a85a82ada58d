// A history request as it arrives over DDS (CDR bytes, as any participant may send them) → the
// request → the service's answer against a store holding a few objects → the reply on the wire.
// A malformed request gets status "error"; nothing may throw out of answer().
#include "../Fuzz.hpp"

#include <cpm/rtdb/Requests.hpp>
#include <cpm_topic_types.hpp>

#include <HistoryReplyPubSubTypes.h>

#include <algorithm>

namespace fuzz_history_request {

const cpm::rtdb::Store& store()
{
    static const auto* s = [] {
        auto* st = new cpm::rtdb::Store;
        for (const char* key : {"3", "4"}) {
            const auto oid = st->add_object({.topic = "vehicleState", .key = key, .type_name = "VehicleState", .created_ts = 1});
            for (uint64_t c = 100; c <= 1000; c += 100) {
                const uint8_t b[] = {uint8_t(c / 100), 1, 2, 3};
                st->commit(oid, {c / 10, c / 10, 0, b, sizeof b}, c);
            }
        }
        return st;
    }();
    return *s;
}

}  // namespace fuzz_history_request

CPM_FUZZ_TARGET(history_request)
{
    HistoryRequest rq;
    if (!cpm::TopicType<HistoryRequest>::decode(std::vector<uint8_t>(data, data + size), rq)) return 0;
    // The waiting kinds would block for their timeout, up to 60 s: a millisecond at most here
    // (a timeout above the limit stays, for the check that refuses it).
    if (rq.timeout_ns() <= cpm::rtdb::kMaxTimeoutNs) rq.timeout_ns(std::min<uint64_t>(rq.timeout_ns(), 1'000'000));
    const HistoryReply reply = cpm::rtdb::answer(fuzz_history_request::store(), rq);
    cpm::fuzz::expect(!reply.status().empty(), "a reply without a status");
    cpm::fuzz::expect(reply.status() != "error" || !reply.error().empty(), "an error reply that does not say what is wrong");
    HistoryReplyPubSubType type;
    eprosima::fastrtps::rtps::SerializedPayload_t payload(type.getSerializedSizeProvider(const_cast<HistoryReply*>(&reply))());
    cpm::fuzz::expect(type.serialize(const_cast<HistoryReply*>(&reply), &payload), "the reply does not serialize");
    return 0;
}
