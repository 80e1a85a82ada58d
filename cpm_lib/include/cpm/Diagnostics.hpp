#pragma once
#include <cpm/Error.hpp>

#include <optional>
#include <string>
#include <vector>

/// What cpm says about a file it reads (a scenario, a state machine, a lane graph, a world, a
/// camera, a parameter or calibration file): every finding at once, each with where it is.
namespace cpm {

/// One finding: where (`file:line: path` or `file: path`; the path is a JSON path such as
/// `$.states[2].p` or a YAML path such as `vehicles[0].start`) and what is wrong.
struct Diagnostic
{
    enum class Severity
    {
        error,    ///< the file cannot be used
        warning,  ///< it can, but probably not as meant
    };
    std::string where;
    std::string message;
    Severity severity = Severity::error;
    std::string text() const { return where.empty() ? message : where + ": " + message; }
};

/// A file that cannot be used, with every error found in it; what() lists them a line each.
class FileError : public Error
{
public:
    explicit FileError(std::vector<Diagnostic> errors);
    const std::vector<Diagnostic>& diagnostics() const { return errors_; }
    /// Each diagnostic's text, in order.
    std::vector<std::string> texts() const;

private:
    std::vector<Diagnostic> errors_;
};

/// The outcome of loading a file without throwing: every error and warning; a value only when
/// there is no error.
template <class T>
struct LoadResult
{
    std::optional<T> value;
    std::vector<Diagnostic> errors;
    std::vector<Diagnostic> warnings;
    bool ok() const { return errors.empty() && value.has_value(); }
    /// The value, or a FileError with every error.
    T take_or_throw()
    {
        if (!ok()) throw FileError(errors);
        return std::move(*value);
    }
};

/// Collects the findings of one file. Format-specific checkers (JSON, YAML) build on it; a
/// loader checks everything, then throws or returns every finding at once.
class Checker
{
public:
    explicit Checker(std::string source) : source_(std::move(source)) {}

    /// `path` is where in the document (empty: the file as a whole); `line` 0 when unknown.
    void error(const std::string& path, const std::string& message, int line = 0);
    void warning(const std::string& path, const std::string& message, int line = 0);
    /// `key` found at `path` is none of `known`: says so, with the one meant when it is close.
    void unknown_key(const std::string& path, const std::string& key, const std::vector<std::string>& known, int line = 0);

    const std::string& source() const { return source_; }
    bool ok() const { return errors_.empty(); }
    const std::vector<Diagnostic>& errors() const { return errors_; }
    const std::vector<Diagnostic>& warnings() const { return warnings_; }
    /// Throws FileError with every error when there is one.
    void throw_if_errors() const;
    /// A LoadResult carrying this checker's findings and `value` when there was no error.
    template <class T>
    LoadResult<T> result(std::optional<T> value) const
    {
        LoadResult<T> r{ok() ? std::move(value) : std::nullopt, errors_, warnings_};
        return r;
    }

private:
    std::string where(const std::string& path, int line) const;

    std::string source_;
    std::vector<Diagnostic> errors_;
    std::vector<Diagnostic> warnings_;
};

/// The one of `known` that `word` is probably a typo of (one edit apart, two for words over four
/// letters, a swap counting as one), or nullopt.
std::optional<std::string> did_you_mean(const std::string& word, const std::vector<std::string>& known);

}  // namespace cpm
