#include <cpm/rtdb/Csv.hpp>

#include <cpm/Error.hpp>
#include <cpm/rtdb/Recording.hpp>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <unistd.h>

namespace cpm::rtdb::csv {

namespace {

std::string cell_of(const nlohmann::json& v)
{
    if (v.is_number_float()) {
        const double d = v.get<double>();
        if (std::isnan(d)) return "nan";
        if (std::isinf(d)) return d > 0 ? "inf" : "-inf";
        return v.dump();  // the shortest text that reads back as the same double
    }
    if (v.is_string()) return v.get<std::string>();
    return v.dump();
}

void flatten_into(const nlohmann::json& data, const std::string& prefix, std::vector<std::pair<std::string, std::string>>& out)
{
    for (auto it = data.begin(); it != data.end(); ++it) {
        const std::string path = prefix.empty() ? it.key() : prefix + "." + it.key();
        if (it->is_object()) flatten_into(*it, path, out);
        else out.emplace_back(path, cell_of(*it));
    }
}

/// Puts a cell's text at its path in the sample's JSON.
void place(nlohmann::json& sample, const std::string& path, const std::string& text)
{
    nlohmann::json* at = &sample;
    size_t start = 0;
    for (size_t dot; (dot = path.find('.', start)) != std::string::npos; start = dot + 1) at = &(*at)[path.substr(start, dot - start)];
    (*at)[path.substr(start)] = text;
}

}  // namespace

std::vector<std::pair<std::string, std::string>> flatten(const nlohmann::json& data)
{
    std::vector<std::pair<std::string, std::string>> out;
    flatten_into(data, "", out);
    return out;
}

std::vector<std::pair<std::string, std::string>> flatten(const nlohmann::json& data, const std::vector<std::string>& paths)
{
    std::vector<std::pair<std::string, std::string>> out;
    for (const auto& path : paths) {
        std::string pointer = "/" + path;
        std::replace(pointer.begin(), pointer.end(), '.', '/');
        const nlohmann::json::json_pointer p(pointer);
        out.emplace_back(path, data.contains(p) ? cell_of(data.at(p)) : std::string());
    }
    return out;
}

std::string line(const std::vector<std::string>& cells)
{
    std::string out;
    for (size_t i = 0; i < cells.size(); ++i) {
        if (i) out += ',';
        const std::string& c = cells[i];
        if (c.find_first_of(",\"\r\n") == std::string::npos) {
            out += c;
            continue;
        }
        out += '"';
        for (char ch : c) out += ch == '"' ? std::string("\"\"") : std::string(1, ch);
        out += '"';
    }
    return out + "\n";
}

bool read_record(std::istream& in, std::vector<std::string>& cells, size_t& line_no)
{
    cells.clear();
    int ch = in.get();
    if (ch == EOF) return false;
    ++line_no;
    const size_t first_line = line_no;
    std::string cell;
    bool quoted = false, was_quoted = false;
    size_t column = 1;
    for (;; ch = in.get()) {
        if (quoted) {
            if (ch == EOF) {
                throw Error("line " + std::to_string(first_line) + ", column " + std::to_string(column) +
                                            ": a quoted cell is never closed");
            }
            if (ch == '"') {
                if (in.peek() == '"') {
                    in.get();
                    cell += '"';
                } else {
                    quoted = false;
                }
            } else {
                if (ch == '\n') ++line_no;
                cell += char(ch);
            }
            continue;
        }
        if (ch == ',' || ch == '\n' || ch == EOF) {
            cells.push_back(std::move(cell));
            cell.clear();
            was_quoted = false;
            ++column;
            if (ch != ',') return true;
            continue;
        }
        if (ch == '\r' && (in.peek() == '\n' || in.peek() == EOF)) continue;
        if (ch == '"' && cell.empty() && !was_quoted) {
            quoted = was_quoted = true;
            continue;
        }
        if (was_quoted) {
            throw Error("line " + std::to_string(line_no) + ", column " + std::to_string(column) +
                                        ": text after a quoted cell's closing quote");
        }
        cell += char(ch);
    }
}

ImportReport import(std::istream& in, const std::string& source, const std::string& topic, const std::string& type,
                    const IdlDecoder& types, const std::string& out_path)
{
    if (!types.knows(type)) throw Error(source + ": type " + type + " is not one of cpm's types (its IDL is needed to write samples)");
    std::vector<std::string> header;
    size_t line_no = 0;
    try {
        if (!read_record(in, header, line_no)) throw Error("empty (the first line names the columns)");
    } catch (const Error& e) {
        throw Error(source + ": " + e.what());
    }
    // Which columns are which; a field column must be one of the type's fields.
    std::map<std::string, size_t> named;
    for (size_t i = 0; i < header.size(); ++i) {
        if (!named.emplace(header[i], i).second) throw Error(source + ":1: column " + header[i] + " comes twice");
    }
    const std::vector<std::string> fields = types.field_paths(type);
    for (size_t i = 0; i < header.size(); ++i) {
        const bool time = std::find(time_columns().begin(), time_columns().end(), header[i]) != time_columns().end();
        if (!time && std::find(fields.begin(), fields.end(), header[i]) == fields.end()) {
            throw Error(source + ":1: column " + std::to_string(i + 1) + " '" + header[i] + "' is no field of " + type);
        }
    }
    auto column = [&](const std::string& name) { return named.count(name) ? std::optional<size_t>(named[name]) : std::nullopt; };
    const auto commit_col = column("commit_ns"), data_col = column("data_ns"), valid_col = column("valid_after_ns");
    const bool header_time = types.has_header(type);
    if (!commit_col && !data_col && !(header_time && named.count("header.create_stamp.nanoseconds"))) {
        throw Error(source + ":1: no time column (commit_ns, data_ns or header.create_stamp.nanoseconds)");
    }

    struct Row
    {
        uint64_t commit = 0, data = 0, valid = 0;
        std::string key;
        std::vector<uint8_t> payload;
    };
    std::vector<Row> rows;
    std::vector<std::string> errors;
    size_t more_errors = 0;
    auto report = [&](size_t line, const std::string& what) {
        if (errors.size() < 20) errors.push_back(source + ":" + std::to_string(line) + ": " + what);
        else ++more_errors;
    };
    std::vector<std::string> cells;
    for (;;) {
        size_t at = line_no;
        try {
            if (!read_record(in, cells, line_no)) break;
        } catch (const Error& e) {
            report(at + 1, e.what());
            break;  // the rest of the file cannot be split into cells
        }
        at = line_no;
        if (cells.size() == 1 && cells[0].empty()) continue;  // a blank line
        if (cells.size() != header.size()) {
            report(at, std::to_string(cells.size()) + " cells, the header names " + std::to_string(header.size()));
            continue;
        }
        nlohmann::json sample = nlohmann::json::object();
        for (size_t i = 0; i < cells.size(); ++i) {
            if (std::find(time_columns().begin(), time_columns().end(), header[i]) == time_columns().end()) place(sample, header[i], cells[i]);
        }
        Row r;
        try {
            r.payload = types.encode(type, sample);
        } catch (const Error& e) {
            const std::string what = e.what();
            const std::string path = what.substr(0, what.find(':'));
            std::string col = path;
            const auto bracket = col.find('[');
            if (bracket != std::string::npos) col = col.substr(0, bracket);
            report(at, "column " + col + (named.count(col) ? " (" + std::to_string(named[col] + 1) + ")" : "") + ": " + what.substr(what.find(':') + 2));
            continue;
        }
        auto time_of = [&](const std::optional<size_t>& col, const std::string& name, uint64_t fallback) -> std::optional<uint64_t> {
            if (!col) return fallback;
            const std::string& t = cells[*col];
            char* end = nullptr;
            errno = 0;
            const unsigned long long v = std::strtoull(t.c_str(), &end, 10);
            if (t.empty() || *end || errno || t[0] == '-') {
                report(at, "column " + name + " (" + std::to_string(*col + 1) + "): '" + t + "' is not a time in nanoseconds");
                return std::nullopt;
            }
            return v;
        };
        const auto decoded = types.decode(type, r.payload);
        const uint64_t stamp = header_time ? decoded->at("header").at("create_stamp").at("nanoseconds").get<uint64_t>() : 0;
        const uint64_t stamp_valid = header_time ? decoded->at("header").at("valid_after_stamp").at("nanoseconds").get<uint64_t>() : 0;
        const auto data = time_of(data_col, "data_ns", stamp);
        if (!data) continue;
        const auto valid = time_of(valid_col, "valid_after_ns", header_time ? stamp_valid : *data);
        const auto commit = time_of(commit_col, "commit_ns", *data);
        if (!valid || !commit) continue;
        r.data = *data;
        r.valid = *valid;
        r.commit = *commit;
        r.key = types.key_text(type, r.payload.data(), r.payload.size()).value_or("");
        rows.push_back(std::move(r));
    }
    if (!errors.empty()) {
        std::string all;
        for (const auto& e : errors) all += (all.empty() ? "" : "\n") + e;
        if (more_errors) all += "\nand " + std::to_string(more_errors) + " more rows that do not parse";
        throw Error(all);
    }
    if (rows.empty()) throw Error(source + ": no rows after the header");

    // The file, as a history service would have written it: an object per key, each sample
    // committed at its commit time (one per object strictly increasing: ties move on by 1 ns).
    std::stable_sort(rows.begin(), rows.end(), [](const Row& a, const Row& b) { return a.commit < b.commit; });
    ImportReport out;
    std::unique_ptr<RecordingWriter> writer_owner = std::make_unique<RecordingWriter>(out_path, RecordingOptions{.name = "import of " + source});
    try {
        RecordingWriter& writer = *writer_owner;
        Store store(StoreOptions{.default_retention = {.window_ns = uint64_t(1) << 62, .max_bytes_per_topic = ~0ull / 4},
                                 .max_bytes_total = ~0ull / 4});
        std::map<std::string, Oid> objects;
        for (const Row& r : rows) {
            auto it = objects.find(r.key);
            if (it == objects.end()) {
                const Oid oid = store.add_object({.topic = topic, .key = r.key, .type_name = type, .creator = "cpm record import",
                                                  .created_ts = r.commit});
                writer.object_added(*store.info(oid));
                it = objects.emplace(r.key, oid).first;
            }
            Incoming in{r.data, r.valid, 0, r.payload.data(), r.payload.size(), 0};
            writer.sample_committed(it->second, in, store.commit(it->second, in, r.commit));
        }
        writer.close();
        if (writer.counters().failed) throw Error(writer.counters().error);
        out.rows = rows.size();
        out.objects = objects.size();
    } catch (...) {
        writer_owner.reset();
        ::unlink(out_path.c_str());  // made by this import: no half file is left
        throw;
    }
    return out;
}

}  // namespace cpm::rtdb::csv
