#include <cpm/QosOverrides.hpp>

#include <cpm/Error.hpp>

#include <nlohmann/json.hpp>

#include <cstdlib>
#include <mutex>

namespace cpm {

QosOverrides parse_qos_overrides(const std::string& json, const std::string& source)
{
    nlohmann::json root;
    try {
        root = nlohmann::json::parse(json);
    } catch (const std::exception& e) {
        throw Error(source + ": not JSON: " + e.what());
    }
    if (!root.is_object()) throw Error(source + ": expected an object of topic: {reliable, transient_local, history_depth}");
    QosOverrides out;
    for (const auto& [topic, spec] : root.items()) {
        const std::string path = source + ": " + topic;
        if (!spec.is_object()) throw Error(path + ": expected an object (reliable, transient_local, history_depth)");
        QosOverride o;
        for (const auto& [key, value] : spec.items()) {
            if (key == "reliable" || key == "transient_local") {
                if (!value.is_boolean()) throw Error(path + "." + key + ": " + value.dump() + " is not true or false");
                (key == "reliable" ? o.reliable : o.transient_local) = value.get<bool>();
            } else if (key == "history_depth") {
                if (!value.is_number_integer() || value.get<long long>() < 1 || value.get<long long>() > 100000) {
                    throw Error(path + ".history_depth: " + value.dump() + " is not a whole number from 1 to 100000");
                }
                o.history_depth = value.get<int>();
            } else {
                throw Error(path + "." + key + ": unknown key; known: reliable, transient_local, history_depth");
            }
        }
        out[topic] = o;
    }
    return out;
}

std::string to_json(const QosOverrides& overrides)
{
    nlohmann::json root = nlohmann::json::object();
    for (const auto& [topic, o] : overrides) {
        nlohmann::json spec = nlohmann::json::object();
        if (o.reliable) spec["reliable"] = *o.reliable;
        if (o.transient_local) spec["transient_local"] = *o.transient_local;
        if (o.history_depth) spec["history_depth"] = *o.history_depth;
        root[topic] = spec;
    }
    return root.dump();
}

QosOverrides qos_overrides()
{
    static std::mutex mutex;
    static std::string seen;
    static QosOverrides parsed;
    const char* value = std::getenv(kQosOverridesVariable);
    const std::string text = value ? value : "";
    std::lock_guard<std::mutex> lock(mutex);
    if (text != seen) {
        parsed = text.empty() ? QosOverrides{} : parse_qos_overrides(text, kQosOverridesVariable);
        seen = text;
    }
    return parsed;
}

namespace {

template <class Options>
Options apply(Options options, const std::string& topic, const QosOverrides& overrides)
{
    const auto found = overrides.find(topic);
    if (found == overrides.end()) return options;
    const QosOverride& o = found->second;
    if (o.reliable) options.reliable = *o.reliable;
    if (o.transient_local) options.transient_local = *o.transient_local;
    if (o.history_depth) {
        options.keep_all = false;
        options.history_depth = *o.history_depth;
    }
    return options;
}

}  // namespace

WriterOptions overridden(WriterOptions options, const std::string& topic, const QosOverrides& overrides)
{
    return apply(options, topic, overrides);
}

ReaderOptions overridden(ReaderOptions options, const std::string& topic, const QosOverrides& overrides)
{
    return apply(options, topic, overrides);
}

}  // namespace cpm
