#include <cpm/ParameterServer.hpp>
#include <cpm/read_text_file.hpp>
#include <cpm/topics.hpp>

#include <cpm/AsyncReader.hpp>
#include <cpm/Error.hpp>
#include <cpm/Writer.hpp>

#include "parameter_types.hpp"

#include <Parameter.h>
#include <ParameterRequest.h>

#include <nlohmann/json.hpp>
#include <yaml-cpp/yaml.h>

#include <cstdlib>

#include <fstream>
#include <limits>
#include <map>
#include <mutex>

namespace cpm {

using detail::parameter_type_name;
using detail::parameter_type_named;

struct ParameterServer::Impl
{
    explicit Impl(Participant& participant)
        : writer(participant, topics::parameter.name, topics::parameter.writer),
          requests(
              [this](std::vector<ParameterRequest>& batch) {
                  for (const auto& r : batch) answer(r.name());
              },
              participant, topics::parameter_request.name, topics::parameter_request.reader)
    {
    }
    // Keyed by name and transient-local (topics::parameter): a client that starts late gets every current value.

    void publish(Parameter p)
    {
        {
            std::lock_guard<std::mutex> lock(mutex);
            values[p.name()] = p;
        }
        (void)writer.write(p);
    }
    void answer(const std::string& name)
    {
        Parameter reply;
        {
            std::lock_guard<std::mutex> lock(mutex);
            auto found = values.find(name);
            if (found != values.end()) {
                reply = found->second;
            } else {
                reply.name(name);
                reply.type(ParameterType_Invalid);
            }
        }
        (void)writer.write(reply);
    }

    mutable std::mutex mutex;
    std::map<std::string, Parameter> values;
    Writer<Parameter> writer;
    AsyncReader<ParameterRequest> requests;  // last: its thread uses the members above
};

namespace {

Parameter make(const std::string& name, ParameterType type)
{
    if (name.empty()) throw Error("ParameterServer: a parameter name is empty");
    Parameter p;
    p.name(name);
    p.type(type);
    return p;
}

bool fits_int32(const nlohmann::json& v)
{
    if (!v.is_number_integer()) return false;
    if (v.is_number_unsigned()) return v.get<uint64_t>() <= uint64_t(std::numeric_limits<int32_t>::max());
    const int64_t i = v.get<int64_t>();
    return i >= std::numeric_limits<int32_t>::min() && i <= std::numeric_limits<int32_t>::max();
}

// The type a plain value stands for: true/false; a whole number fitting int32 -> int, larger
// -> uint64; other numbers -> double; text; a list of int32 numbers -> ints, of numbers -> doubles.
ParameterType inferred_type(const nlohmann::json& v, const std::string& where)
{
    if (v.is_boolean()) return ParameterType_Bool;
    if (fits_int32(v)) return ParameterType_Int32;
    if (v.is_number_unsigned()) return ParameterType_UInt64;
    if (v.is_number()) return ParameterType_Double;
    if (v.is_string()) return ParameterType_String;
    if (v.is_array() && !v.empty()) {
        bool all_int32 = true;
        for (const auto& e : v) {
            if (!e.is_number()) throw Error(where + ": a list must hold only numbers");
            all_int32 = all_int32 && fits_int32(e);
        }
        return all_int32 ? ParameterType_Vector_Int32 : ParameterType_Vector_Double;
    }
    throw Error(where + ": " + v.dump() + " is not a parameter value (bool, number, text or list of numbers)");
}

// A parameter of the given type from a JSON value; `where` names the file and JSON path.
Parameter typed(const std::string& name, ParameterType type, const nlohmann::json& value, const std::string& where)
{
    auto require = [&](bool ok) {
        if (!ok) throw Error(where + ": value " + value.dump() + " is not of type " + parameter_type_name(type));
    };
    Parameter p = make(name, type);
    switch (type) {
        case ParameterType_Bool:
            require(value.is_boolean());
            p.value_bool(value.get<bool>());
            break;
        case ParameterType_Int32:
            require(fits_int32(value));
            p.values_int32({value.get<int32_t>()});
            break;
        case ParameterType_UInt64:
            require(value.is_number_unsigned());
            p.values_uint64({value.get<uint64_t>()});
            break;
        case ParameterType_Double:
            require(value.is_number());
            p.values_double({value.get<double>()});
            break;
        case ParameterType_String:
            require(value.is_string());
            p.value_string(value.get<std::string>());
            break;
        case ParameterType_Vector_Int32:
            require(value.is_array());
            for (const auto& e : value) require(fits_int32(e));  // never truncate silently
            p.values_int32(value.get<std::vector<int32_t>>());
            break;
        case ParameterType_Vector_Double:
            require(value.is_array());
            for (const auto& e : value) require(e.is_number());
            p.values_double(value.get<std::vector<double>>());
            break;
        default:
            throw Error(where + ": no such parameter type");
    }
    return p;
}

// One parameter from a JSON value: {"type": ..., "value": ...}, or a plain value.
Parameter from_json(const std::string& name, const nlohmann::json& v, const std::string& where)
{
    if (!v.is_object()) return typed(name, inferred_type(v, where), v, where);
    if (!v.contains("type") || !v.contains("value") || !v["type"].is_string()) {
        throw Error(where + ": an object must be {\"type\": ..., \"value\": ...}");
    }
    const std::string type = v["type"];
    const auto known = parameter_type_named(type);
    if (!known) throw Error(where + ": unknown type '" + type + "' (bool, int, uint64, double, string, ints, doubles)");
    return typed(name, *known, v["value"], where);
}

// A YAML document as JSON, so both formats share one set of type rules.
nlohmann::json yaml_to_json(const YAML::Node& node, const std::string& where)
{
    switch (node.Type()) {
        case YAML::NodeType::Map: {
            nlohmann::json object = nlohmann::json::object();
            for (const auto& entry : node) {
                const std::string key = entry.first.as<std::string>();
                object[key] = yaml_to_json(entry.second, where + "/" + key);
            }
            return object;
        }
        case YAML::NodeType::Sequence: {
            nlohmann::json array = nlohmann::json::array();
            for (const auto& item : node) array.push_back(yaml_to_json(item, where));
            return array;
        }
        case YAML::NodeType::Scalar: {
            const std::string text = node.Scalar();
            if (node.Tag() == "!") return text;  // quoted: always text
            if (text == "true" || text == "True" || text == "TRUE") return true;
            if (text == "false" || text == "False" || text == "FALSE") return false;
            char* end = nullptr;
            if (!text.empty() && text.find_first_not_of("+-0123456789") == std::string::npos) {
                if (text[0] == '-') {
                    const long long v = std::strtoll(text.c_str(), &end, 10);
                    if (*end == '\0') return v;
                } else {
                    const unsigned long long v = std::strtoull(text.c_str(), &end, 10);
                    if (*end == '\0') return v;
                }
            }
            const double d = std::strtod(text.c_str(), &end);
            if (!text.empty() && *end == '\0') return d;
            return text;
        }
        default:
            throw Error(where + " (line " + std::to_string(node.Mark().line + 1) + "): empty value");
    }
}

// Every parameter of a document, all checked before any is published.
std::vector<Parameter> parameters_of(const nlohmann::json& doc, const std::string& path)
{
    if (!doc.is_object()) throw Error("parameter file '" + path + "': the top level must be an object of parameters");
    std::vector<Parameter> loaded;
    for (const auto& [name, value] : doc.items()) {
        loaded.push_back(from_json(name, value, "parameter file '" + path + "' at /" + name));
    }
    return loaded;
}

}  // namespace

ParameterServer::ParameterServer(Participant& participant) : impl_(std::make_unique<Impl>(participant)) {}
ParameterServer::~ParameterServer() = default;

void ParameterServer::set_bool(const std::string& name, bool value)
{
    auto p = make(name, ParameterType_Bool);
    p.value_bool(value);
    impl_->publish(p);
}
void ParameterServer::set_int(const std::string& name, int32_t value)
{
    auto p = make(name, ParameterType_Int32);
    p.values_int32({value});
    impl_->publish(p);
}
void ParameterServer::set_uint64(const std::string& name, uint64_t value)
{
    auto p = make(name, ParameterType_UInt64);
    p.values_uint64({value});
    impl_->publish(p);
}
void ParameterServer::set_double(const std::string& name, double value)
{
    auto p = make(name, ParameterType_Double);
    p.values_double({value});
    impl_->publish(p);
}
void ParameterServer::set_string(const std::string& name, const std::string& value)
{
    auto p = make(name, ParameterType_String);
    p.value_string(value);
    impl_->publish(p);
}
void ParameterServer::set_ints(const std::string& name, const std::vector<int32_t>& values)
{
    auto p = make(name, ParameterType_Vector_Int32);
    p.values_int32(values);
    impl_->publish(p);
}
void ParameterServer::set_doubles(const std::string& name, const std::vector<double>& values)
{
    auto p = make(name, ParameterType_Vector_Double);
    p.values_double(values);
    impl_->publish(p);
}

size_t ParameterServer::load_json_file(const std::string& path)
{
    const std::string text = read_text_file(path, "parameter file");
    nlohmann::json doc;
    try {
        doc = nlohmann::json::parse(text);
    } catch (const nlohmann::json::exception& e) {
        throw Error("parameter file '" + path + "': not valid JSON: " + e.what());
    }
    return publish_all(parameters_of(doc, path));
}

size_t ParameterServer::load_yaml_file(const std::string& path)
{
    YAML::Node doc;
    try {
        doc = YAML::LoadFile(path);
    } catch (const YAML::BadFile&) {
        throw Error("parameter file '" + path + "': cannot be opened");
    } catch (const YAML::ParserException& e) {
        throw Error("parameter file '" + path + "' line " + std::to_string(e.mark.line + 1) + ": not valid YAML: " +
                    e.msg);
    }
    if (!doc.IsMap()) throw Error("parameter file '" + path + "': the top level must be a mapping of parameters");
    return publish_all(parameters_of(yaml_to_json(doc, "parameter file '" + path + "' at "), path));
}

size_t ParameterServer::load_file(const std::string& path)
{
    const auto dot = path.rfind('.');
    const std::string ext = dot == std::string::npos ? "" : path.substr(dot);
    return ext == ".yaml" || ext == ".yml" ? load_yaml_file(path) : load_json_file(path);
}



size_t ParameterServer::publish_all(const std::vector<Parameter>& parameters)
{
    // Known to requests all at once, before any is announced.
    {
        std::lock_guard<std::mutex> lock(impl_->mutex);
        for (const auto& p : parameters) impl_->values[p.name()] = p;
    }
    for (const auto& p : parameters) impl_->publish(p);
    return parameters.size();
}

size_t ParameterServer::size() const
{
    std::lock_guard<std::mutex> lock(impl_->mutex);
    return impl_->values.size();
}

}  // namespace cpm
