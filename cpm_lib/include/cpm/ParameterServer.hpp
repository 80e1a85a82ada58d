#pragma once
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <cpm/Participant.hpp>

class Parameter;  // the generated IDL type

namespace cpm {

/// Serves named, typed values on topic `parameter` (reliable, transient-local, keyed by name:
/// clients that start later get every current value) and answers `ParameterRequest`s; an
/// unknown name is answered with type Invalid, so a client fails at once instead of waiting.
/// Setting a value publishes it immediately. Thread-safe.
class ParameterServer
{
public:
    explicit ParameterServer(Participant& participant);
    ~ParameterServer();
    ParameterServer(const ParameterServer&) = delete;
    ParameterServer& operator=(const ParameterServer&) = delete;

    void set_bool(const std::string& name, bool value);
    void set_int(const std::string& name, int32_t value);
    void set_uint64(const std::string& name, uint64_t value);
    void set_double(const std::string& name, double value);
    void set_string(const std::string& name, const std::string& value);
    void set_ints(const std::string& name, const std::vector<int32_t>& values);
    void set_doubles(const std::string& name, const std::vector<double>& values);

    /// Loads a JSON object of parameters: `{"name": value, ...}` with the type taken from the
    /// value (true/false; a whole number fitting int32 -> int, larger -> uint64; other numbers ->
    /// double; text; a list of whole numbers -> ints, of numbers -> doubles), or
    /// `{"name": {"type": "bool|int|uint64|double|string|ints|doubles", "value": ...}}`.
    /// Throws cpm::Error naming the file and the JSON path (or line) of what is wrong; loads
    /// nothing then. Returns the number of parameters loaded.
    size_t load_json_file(const std::string& path);
    /// The same from YAML: a mapping of names to values (or to {type, value} mappings); quoted
    /// scalars are text, plain ones are read as true/false, whole numbers or numbers where they
    /// parse as such. Errors name the file and the line.
    size_t load_yaml_file(const std::string& path);
    /// load_yaml_file for .yaml/.yml, else load_json_file.
    size_t load_file(const std::string& path);

    size_t size() const;

private:
    size_t publish_all(const std::vector<::Parameter>& parameters);
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace cpm
