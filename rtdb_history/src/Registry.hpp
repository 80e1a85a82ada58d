#pragma once
// The history service's registry: which objects it has made for what it sees — a process
// object per participant, an instance object per topic instance — and which writers keep each
// instance alive. An instance ends when it is disposed, or when its last writer or that
// writer's process leaves. Not thread-safe: the ingest calls it under its lock.
#include "Outlet.hpp"
#include "RawType.hpp"

#include <fastdds/rtps/common/Guid.h>
#include <fastdds/rtps/common/InstanceHandle.h>

#include <functional>
#include <map>
#include <set>
#include <string>

namespace cpm::rtdb {

namespace rtps = eprosima::fastrtps::rtps;

class Registry
{
public:
    explicit Registry(Outlet& out) : out_(out) {}

    /// A participant found. One seen again after it was lost (its lease ran out while it or
    /// this process was stopped) is a new process object, as in KogMo-RTDB.
    void process_found(const rtps::GuidPrefix_t& prefix, const std::string& name, uint64_t now);
    /// A participant gone: its object is deleted, and with its writers every instance they kept.
    void process_gone(const rtps::GuidPrefix_t& prefix, uint64_t now);
    void writer_gone(const std::string& topic, const rtps::GUID_t& writer, uint64_t now);

    /// What a new instance object is called; asked only when one is made.
    struct Naming
    {
        std::string key, type_name, data_time;
    };
    /// The object a sample of this instance goes to, made on its first sample (or the first
    /// after it ended); the writer keeps it alive. kNoOid when the store holds too many objects.
    Oid instance(const std::string& topic, const rtps::InstanceHandle_t& handle, const rtps::GUID_t& writer,
                 const std::function<Naming()>& naming, uint64_t now);
    /// Disposed or unregistered by its writer.
    void instance_ended(const std::string& topic, const rtps::InstanceHandle_t& handle, uint64_t now);

private:
    struct InstanceRec
    {
        Oid oid = kNoOid;
        std::set<rtps::GUID_t> writers;
        bool deleted = false;
    };
    struct ProcessRec
    {
        Oid oid = kNoOid;
        std::string name;
        bool gone = false;
    };
    void end(InstanceRec& inst, uint64_t now);

    Outlet& out_;
    std::map<std::string, std::map<rtps::InstanceHandle_t, InstanceRec>> instances_;  ///< by topic
    std::map<rtps::GuidPrefix_t, ProcessRec> processes_;
};

}  // namespace cpm::rtdb
