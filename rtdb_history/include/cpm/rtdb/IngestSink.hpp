#pragma once
// cpm::rtdb::IngestSink — where the history service's ingest hands on what it records, in the
// order it happens. The service's Store is always the first sink (it gives each object its
// oid); further sinks in ServiceOptions::sinks see the same objects, samples and deletions with
// the same oids and commit times (a recording file is fed from here).
//
// Calls come from the service's ingest path, one at a time (never concurrently), while the
// ingest holds its lock: keep them short, never call back into the service, never throw (an
// exception is logged and the sink is not called again).
#include <cpm/rtdb/Store.hpp>

namespace cpm::rtdb {

class IngestSink
{
public:
    virtual ~IngestSink() = default;
    /// A new object (an instance seen for the first time, or a process), info.oid set.
    virtual void object_added(const ObjectInfo& info) = 0;
    /// A sample of an object, committed to the store at commit_ns; the payload is valid only
    /// during the call.
    virtual void sample_committed(Oid oid, const Incoming& sample, uint64_t commit_ns) = 0;
    /// The object's instance was disposed, its last writer or its process left.
    virtual void object_deleted(Oid oid, uint64_t deleted_ns) = 0;
};

}  // namespace cpm::rtdb
