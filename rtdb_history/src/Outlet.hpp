#pragma once
// Where the ingest's objects, samples and deletions leave it: the store first (it gives the
// oids), then every further sink (ServiceOptions::sinks). Called under the ingest's lock.
#include <cpm/Logging.hpp>
#include <cpm/rtdb/IngestSink.hpp>
#include <cpm/rtdb/Store.hpp>

#include <algorithm>
#include <memory>
#include <vector>

namespace cpm::rtdb {

class Outlet
{
public:
    Outlet(Store& store, std::vector<std::shared_ptr<IngestSink>> sinks) : store_(store), sinks_(std::move(sinks)) {}

    /// Throws cpm::Error, as Store::add_object, when the store holds too many objects.
    Oid add(ObjectInfo info)
    {
        const Oid oid = store_.add_object(std::move(info));
        if (!sinks_.empty()) {
            const auto held = store_.info(oid);  // as the store completed it: name, history interval
            each([&](IngestSink& s) { s.object_added(*held); });
        }
        return oid;
    }
    void commit(Oid oid, const Incoming& sample, uint64_t now)
    {
        const uint64_t commit_ns = store_.commit(oid, sample, now);  // a tie moves on by 1 ns
        each([&](IngestSink& s) { s.sample_committed(oid, sample, commit_ns); });
    }
    void deleted(Oid oid, uint64_t now)
    {
        store_.mark_deleted(oid, now);
        each([&](IngestSink& s) { s.object_deleted(oid, now); });
    }

    /// A sink from now on (a save), until removed; under the ingest's lock as every call here.
    void add_sink(std::shared_ptr<IngestSink> sink) { sinks_.push_back(std::move(sink)); }
    void remove_sink(const IngestSink* sink)
    {
        sinks_.erase(std::remove_if(sinks_.begin(), sinks_.end(), [&](const auto& s) { return s.get() == sink; }), sinks_.end());
    }

private:
    /// A sink that throws is logged once and left out from then on; the store and the other
    /// sinks go on.
    template <class F>
    void each(F&& call)
    {
        for (auto& sink : sinks_) {
            if (!sink) continue;
            try {
                call(*sink);
            } catch (const std::exception& e) {
                CPM_LOG_ERROR("cpm_history: a sink failed and gets nothing more: %s", e.what());
                sink.reset();
            }
        }
    }

    Store& store_;
    std::vector<std::shared_ptr<IngestSink>> sinks_;
};

}  // namespace cpm::rtdb
