#include <cpm/get_parameter.hpp>

#include <cpm/AsyncReader.hpp>
#include <cpm/Error.hpp>
#include <cpm/Writer.hpp>
#include <cpm/topics.hpp>

#include "UntilExit.hpp"
#include "parameter_types.hpp"

#include <Parameter.h>
#include <ParameterRequest.h>

#include <condition_variable>
#include <map>
#include <functional>
#include <mutex>

namespace cpm {

namespace {

// The values this process has seen, kept current by the server's announcements.
class ParameterCache
{
public:
    static ParameterCache& instance()
    {
        static ParameterCache* cache = new ParameterCache();  // never destroyed, like Logging
        return *cache;
    }

    Parameter get(const std::string& name, ParameterType wanted, std::chrono::milliseconds timeout)
    {
        const auto deadline = std::chrono::steady_clock::now() + timeout;
        // "Unknown" answers within the first second are asked again: a server that is still
        // loading its file answers before it knows everything.
        const auto grace_end = std::min(deadline, std::chrono::steady_clock::now() + std::chrono::seconds(1));
        std::unique_lock<std::mutex> lock(mutex_);
        for (;;) {
            wait_for_answer(lock, name, deadline, timeout);
            if (values_.at(name).type() != ParameterType_Invalid) break;
            values_.erase(name);  // it may be added to the server later
            if (std::chrono::steady_clock::now() >= grace_end) {
                throw Error("parameter '" + name + "': the parameter server does not know it");
            }
            changed_.wait_until(lock, std::min(grace_end, std::chrono::steady_clock::now() + std::chrono::milliseconds(100)));
        }
        const Parameter& p = values_.at(name);
        if (p.type() != wanted) {
            throw Error("parameter '" + name + "' is of type " + detail::parameter_type_name(p.type()) + ", not " + detail::parameter_type_name(wanted));
        }
        return p;
    }

private:
    // Until a value (or an "unknown") for name is cached: asks, and again every 500 ms in case
    // the server came up after the first request. Throws at the deadline.
    void wait_for_answer(std::unique_lock<std::mutex>& lock, const std::string& name,
                         std::chrono::steady_clock::time_point deadline, std::chrono::milliseconds timeout)
    {
        while (!values_.count(name)) {
            lock.unlock();
            ParameterRequest request;
            request.name(name);
            if (auto use = dds_.use()) (void)use->requests.write(request);
            lock.lock();
            const auto wake = std::min(deadline, std::chrono::steady_clock::now() + std::chrono::milliseconds(500));
            changed_.wait_until(lock, wake, [&] { return values_.count(name) > 0; });
            if (!values_.count(name) && std::chrono::steady_clock::now() >= deadline) {
                throw Error("parameter '" + name + "': no answer from a parameter server within " +
                            std::to_string(timeout.count()) + " ms");
            }
        }
    }

    ParameterCache()
    {
        dds_.set(std::make_unique<Dds>([this](std::vector<Parameter>& batch) {
            {
                std::lock_guard<std::mutex> lock(mutex_);
                for (auto& p : batch) values_[p.name()] = p;
            }
            changed_.notify_all();
        }));
    }

    /// On the default participant; destroyed at exit, the cache itself never.
    struct Dds
    {
        explicit Dds(std::function<void(std::vector<Parameter>&)> on_values)
            : requests(topics::parameter_request.name, topics::parameter_request.writer),
              values(std::move(on_values), topics::parameter.name, topics::parameter.reader)
        {
        }
        Writer<ParameterRequest> requests;
        AsyncReader<Parameter> values;
    };

    std::mutex mutex_;
    std::condition_variable changed_;
    std::map<std::string, Parameter> values_;
    detail::UntilExit<Dds> dds_;  // last: its reader's thread uses the members above
};

Parameter fetch(const std::string& name, ParameterType type, std::chrono::milliseconds timeout)
{
    return ParameterCache::instance().get(name, type, timeout);
}

}  // namespace

bool parameter_bool(const std::string& name, std::chrono::milliseconds timeout)
{
    return fetch(name, ParameterType_Bool, timeout).value_bool();
}
int32_t parameter_int(const std::string& name, std::chrono::milliseconds timeout)
{
    return fetch(name, ParameterType_Int32, timeout).values_int32().at(0);
}
uint64_t parameter_uint64_t(const std::string& name, std::chrono::milliseconds timeout)
{
    return fetch(name, ParameterType_UInt64, timeout).values_uint64().at(0);
}
double parameter_double(const std::string& name, std::chrono::milliseconds timeout)
{
    return fetch(name, ParameterType_Double, timeout).values_double().at(0);
}
std::string parameter_string(const std::string& name, std::chrono::milliseconds timeout)
{
    return fetch(name, ParameterType_String, timeout).value_string();
}
std::vector<int32_t> parameter_ints(const std::string& name, std::chrono::milliseconds timeout)
{
    return fetch(name, ParameterType_Vector_Int32, timeout).values_int32();
}
std::vector<double> parameter_doubles(const std::string& name, std::chrono::milliseconds timeout)
{
    return fetch(name, ParameterType_Vector_Double, timeout).values_double();
}

}  // namespace cpm
