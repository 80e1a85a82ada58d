#pragma once
// Samples as CSV and back (the KogMo-RTDB manual's "import simulation data"): one row per
// sample, columns commit_ns, data_ns, valid_after_ns, key, then every field of the type by its
// IDL path (`header.create_stamp.nanoseconds`, `pose.x`); an array or sequence is one cell
// holding a JSON array, an enum its name, NaN and infinities `nan`, `inf`, `-inf`. Cells are
// quoted as RFC 4180 says (a comma, quote or line break inside: in quotes, quotes doubled).
#include <cpm/rtdb/IdlDecoder.hpp>

#include <nlohmann/json.hpp>

#include <cstdint>
#include <istream>
#include <string>
#include <utility>
#include <vector>

namespace cpm::rtdb::csv {

/// The columns that come before the fields.
inline const std::vector<std::string>& time_columns()
{
    static const std::vector<std::string> c = {"commit_ns", "data_ns", "valid_after_ns", "key"};
    return c;
}

/// A decoded sample's fields as (IDL path, cell text), in the order of `paths` (see
/// IdlDecoder::field_paths); a path the sample lacks gives an empty cell.
std::vector<std::pair<std::string, std::string>> flatten(const nlohmann::json& data, const std::vector<std::string>& paths);
/// The same in path order, for a sample whose type's IDL is not at hand.
std::vector<std::pair<std::string, std::string>> flatten(const nlohmann::json& data);

/// One CSV line of these cells, with its line break.
std::string line(const std::vector<std::string>& cells);

/// Reads one record (a quoted cell may span lines). False at the end of the input. `line_no` is
/// the line the record starts on (1-based), counted on. Throws cpm::Error naming the
/// line and column for a quote that is never closed or text after a closing quote.
bool read_record(std::istream& in, std::vector<std::string>& cells, size_t& line_no);

struct ImportReport
{
    uint64_t rows = 0;
    uint64_t objects = 0;
};

/// Reads CSV as export writes it (the header row names the columns; commit_ns, data_ns,
/// valid_after_ns and key are optional: without commit_ns a row is committed at its data time,
/// without data_ns that is the type's header.create_stamp) and writes a new recording at
/// out_path with the samples as topic `topic` of type `type`. Every row that does not parse is
/// reported as "SOURCE:LINE: column NAME (C): what" (at most 20, then "and N more") in one
/// cpm::Error, and no file is left behind.
ImportReport import(std::istream& in, const std::string& source, const std::string& topic, const std::string& type,
                    const IdlDecoder& types, const std::string& out_path);

}  // namespace cpm::rtdb::csv
