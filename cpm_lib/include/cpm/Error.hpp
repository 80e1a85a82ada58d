#pragma once
#include <stdexcept>

namespace cpm {

/// Thrown while constructing or configuring cpm objects; the message names the topic,
/// option or value that is wrong. Reading and writing never throw.
class Error : public std::runtime_error
{
public:
    using std::runtime_error::runtime_error;
};

}  // namespace cpm
