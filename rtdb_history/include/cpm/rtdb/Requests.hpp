#pragma once
// The history service's request handling, without DDS: a HistoryRequest against a Store gives
// the HistoryReply. A malformed request (unknown kind or object, t1 < t0, absurd limits) gets
// status "error" (or "unknown_object") and a message naming the field and value.
#include <cpm/HistoryClient.hpp>
#include <cpm/rtdb/Store.hpp>

#include <HistoryReply.h>
#include <HistoryRequest.h>

namespace cpm::rtdb {

constexpr uint32_t kDefaultLimit = 1000;
constexpr uint32_t kMaxLimit = 100000;
constexpr uint64_t kMaxTimeoutNs = 60'000'000'000ull;

/// Whether the request may block (wait_next, successor, wait_object): the service answers
/// those on worker threads so that they never hold up the others.
bool may_wait(const HistoryRequest& rq);

/// Answers one request (blocking up to its timeout for the waiting kinds).
HistoryReply answer(const Store& store, const HistoryRequest& rq);

/// A HistoryClient's backend that answers from a Store in this process, as the service
/// answers from its own: `cpm::HistoryClient client(std::make_unique<StoreBackend>(store));`.
/// The store must outlive the client.
class StoreBackend final : public cpm::HistoryBackend
{
public:
    explicit StoreBackend(const Store& store) : store_(store) {}
    HistoryReply request(const HistoryRequest& rq) override { return answer(store_, rq); }

private:
    const Store& store_;
};

/// The info block as it goes on the wire.
HistoryObject to_wire(const ObjectInfo& info);

}  // namespace cpm::rtdb
