#include <cpm/Diagnostics.hpp>

#include <algorithm>

namespace cpm {

namespace {

std::string lines_of(const std::vector<Diagnostic>& errors)
{
    std::string out;
    for (const auto& e : errors) out += (out.empty() ? "" : "\n") + e.text();
    return out;
}

/// Edit distance with adjacent swaps (optimal string alignment).
size_t distance(const std::string& a, const std::string& b)
{
    const size_t n = a.size(), m = b.size();
    std::vector<std::vector<size_t>> d(n + 1, std::vector<size_t>(m + 1));
    for (size_t i = 0; i <= n; ++i) d[i][0] = i;
    for (size_t j = 0; j <= m; ++j) d[0][j] = j;
    for (size_t i = 1; i <= n; ++i) {
        for (size_t j = 1; j <= m; ++j) {
            d[i][j] = std::min({d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + (a[i - 1] != b[j - 1])});
            if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1]) d[i][j] = std::min(d[i][j], d[i - 2][j - 2] + 1);
        }
    }
    return d[n][m];
}

}  // namespace

FileError::FileError(std::vector<Diagnostic> errors) : Error(lines_of(errors)), errors_(std::move(errors)) {}

std::vector<std::string> FileError::texts() const
{
    std::vector<std::string> out;
    for (const auto& e : errors_) out.push_back(e.text());
    return out;
}

std::string Checker::where(const std::string& path, int line) const
{
    std::string w = source_;
    if (line > 0) w += ":" + std::to_string(line);
    if (!path.empty()) w += (w.empty() ? "" : ": ") + path;
    return w;
}

void Checker::error(const std::string& path, const std::string& message, int line)
{
    errors_.push_back({where(path, line), message, Diagnostic::Severity::error});
}

void Checker::warning(const std::string& path, const std::string& message, int line)
{
    warnings_.push_back({where(path, line), message, Diagnostic::Severity::warning});
}

void Checker::unknown_key(const std::string& path, const std::string& key, const std::vector<std::string>& known, int line)
{
    std::string all;
    for (const auto& k : known) all += (all.empty() ? "" : ", ") + k;
    const auto meant = did_you_mean(key, known);
    error(path, "unknown key" + (meant ? " (did you mean '" + *meant + "'?)" : std::string()) +
                    (known.empty() ? "; none is known here" : "; known: " + all), line);
}

void Checker::throw_if_errors() const
{
    if (!errors_.empty()) throw FileError(errors_);
}

std::optional<std::string> did_you_mean(const std::string& word, const std::vector<std::string>& known)
{
    std::optional<std::string> best;
    size_t best_d = 0;
    for (const auto& k : known) {
        if (k == word) return std::nullopt;
        const size_t d = distance(word, k);
        if (d > (std::max(word.size(), k.size()) > 4 ? 2u : 1u)) continue;
        if (!best || d < best_d) {
            best = k;
            best_d = d;
        }
    }
    return best;
}

}  // namespace cpm
