#include <cpm/rtdb/Diff.hpp>

#include <cpm/rtdb/IdlDecoder.hpp>
#include <cpm/rtdb/Store.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdio>
#include <map>
#include <set>

namespace cpm::rtdb {
namespace {

using ObjectKey = std::pair<std::string, std::string>;  // topic, key

std::string seconds(uint64_t ns)
{
    char text[48];
    std::snprintf(text, sizeof text, "%llu.%09llu s", (unsigned long long)(ns / 1'000'000'000ull),
                  (unsigned long long)(ns % 1'000'000'000ull));
    return text;
}

std::string name_of(const ObjectKey& k) { return k.second.empty() ? k.first : k.first + "/" + k.second; }

/// Every sample of each topic/key the options ask for, in data-time order (ties by payload).
std::map<ObjectKey, std::pair<std::string, std::vector<StoredSample>>> samples_of(const LoadedRecording& r, const DiffOptions& o)
{
    std::map<ObjectKey, std::pair<std::string, std::vector<StoredSample>>> out;
    Criteria c;
    c.kind = ObjectKind::instance;
    for (const auto& info : r.store->search(c)) {
        if (!o.topics.empty() && std::find(o.topics.begin(), o.topics.end(), info.topic) == o.topics.end()) continue;
        if (std::find(o.exclude.begin(), o.exclude.end(), info.topic) != o.exclude.end()) continue;
        auto& [type, samples] = out[{info.topic, info.key}];
        type = info.type_name;
        for (uint64_t t0 = 0;;) {
            auto range = r.store->range(info.oid, t0, UINT64_MAX, By::commit, 100'000);
            if (range.samples.empty()) break;
            t0 = range.samples.back().commit_ns + 1;
            for (auto& s : range.samples) samples.push_back(std::move(s));
            if (!range.truncated) break;
        }
        std::stable_sort(samples.begin(), samples.end(), [](const StoredSample& x, const StoredSample& y) {
            return x.data_ns != y.data_ns ? x.data_ns < y.data_ns : x.payload < y.payload;
        });
    }
    return out;
}

/// The first leaf that differs between two decoded samples: "pose.x: 1.25 in A, 1.3 in B".
std::string first_field_difference(const nlohmann::json& a, const nlohmann::json& b, const std::string& path)
{
    const auto at = [&](const std::string& child) { return path.empty() ? child : path + child; };
    if (a.is_object() && b.is_object()) {
        for (auto it = a.begin(); it != a.end(); ++it) {
            if (!b.contains(it.key())) return at((path.empty() ? "" : ".") + it.key()) + ": only in A";
            if (auto d = first_field_difference(it.value(), b[it.key()], at((path.empty() ? "" : ".") + it.key())); !d.empty()) return d;
        }
        return "";
    }
    if (a.is_array() && b.is_array()) {
        if (a.size() != b.size()) return (path.empty() ? "the sample" : path) + ": " + std::to_string(a.size()) + " elements in A, " +
                                          std::to_string(b.size()) + " in B";
        for (size_t i = 0; i < a.size(); ++i) {
            if (auto d = first_field_difference(a[i], b[i], path + "[" + std::to_string(i) + "]"); !d.empty()) return d;
        }
        return "";
    }
    if (a == b) return "";
    return (path.empty() ? "the sample" : path) + ": " + a.dump() + " in A, " + b.dump() + " in B";
}

std::string payload_difference(const LoadedRecording& a, const std::string& type, const StoredSample& x, const StoredSample& y)
{
    if (a.types) {
        const auto jx = a.types->decode(type, x.payload), jy = a.types->decode(type, y.payload);
        if (jx && jy) {
            if (auto d = first_field_difference(*jx, *jy, ""); !d.empty()) return d;
        }
    }
    return "payload bytes differ (" + std::to_string(x.payload.size()) + " in A, " + std::to_string(y.payload.size()) + " in B)";
}

}  // namespace

DiffResult diff_recordings(const LoadedRecording& a, const LoadedRecording& b, const DiffOptions& options)
{
    const auto in_a = samples_of(a, options), in_b = samples_of(b, options);
    std::set<ObjectKey> keys;
    for (const auto& [k, v] : in_a) keys.insert(k);
    for (const auto& [k, v] : in_b) keys.insert(k);
    DiffResult result;
    for (const auto& k : keys) {
        ++result.objects;
        const auto fa = in_a.find(k), fb = in_b.find(k);
        SampleDifference d{k.first, k.second};
        if (fa == in_a.end() || fb == in_b.end()) {
            d.what = fa == in_a.end() ? "only in B (A has no " + name_of(k) + ")" : "only in A (B has no " + name_of(k) + ")";
            result.differences.push_back(std::move(d));
            continue;
        }
        const auto& sa = fa->second.second;
        const auto& sb = fb->second.second;
        const size_t n = std::min(sa.size(), sb.size());
        size_t i = 0;
        while (i < n && sa[i].data_ns == sb[i].data_ns && sa[i].payload == sb[i].payload) ++i;
        result.samples += i;
        if (i == n && sa.size() == sb.size()) continue;
        d.index = i;
        d.data_ns_a = i < sa.size() ? sa[i].data_ns : 0;
        d.data_ns_b = i < sb.size() ? sb[i].data_ns : 0;
        if (i == n) {
            d.what = "A has " + std::to_string(sa.size()) + " samples, B " + std::to_string(sb.size()) + "; the first extra one at data time " +
                     seconds(i < sa.size() ? sa[i].data_ns : sb[i].data_ns);
        } else if (sa[i].data_ns != sb[i].data_ns) {
            d.what = "data time " + seconds(sa[i].data_ns) + " in A, " + seconds(sb[i].data_ns) + " in B";
        } else {
            d.what = payload_difference(a, fa->second.first, sa[i], sb[i]);
        }
        result.differences.push_back(std::move(d));
    }
    return result;
}

}  // namespace cpm::rtdb
