#pragma once
// The names of parameter types, as files and error messages spell them; server and client
// share this one table.
#include <Parameter.h>

#include <optional>
#include <string>

namespace cpm::detail {

inline const char* parameter_type_name(ParameterType type)
{
    switch (type) {
        case ParameterType_Bool: return "bool";
        case ParameterType_Int32: return "int";
        case ParameterType_UInt64: return "uint64";
        case ParameterType_Double: return "double";
        case ParameterType_String: return "string";
        case ParameterType_Vector_Int32: return "ints";
        case ParameterType_Vector_Double: return "doubles";
        default: return "unknown";
    }
}

inline std::optional<ParameterType> parameter_type_named(const std::string& name)
{
    for (ParameterType t : {ParameterType_Bool, ParameterType_Int32, ParameterType_UInt64, ParameterType_Double,
                            ParameterType_String, ParameterType_Vector_Int32, ParameterType_Vector_Double}) {
        if (name == parameter_type_name(t)) return t;
    }
    return std::nullopt;
}

}  // namespace cpm::detail
