// bench_table FILE: the figures `./lab bench` recorded (one JSON object per line, see
// bench_common.hpp's Figure) as one table: bench, case, cpm, peer, ratio, target, met.
#include <cpm/CommandLine.hpp>

#include <nlohmann/json.hpp>

#include <cstdio>
#include <fstream>
#include <string>

namespace {

std::string number(const nlohmann::json& v)
{
    if (!v.is_number()) return "-";
    char b[32];
    const double d = v.get<double>();
    std::snprintf(b, sizeof b, d >= 1000 ? "%.0f" : d >= 10 ? "%.1f" : "%.3g", d);
    return b;
}

std::string text(const nlohmann::json& v) { return v.is_string() ? v.get<std::string>() : "-"; }

const char* kHelp =
    "usage: bench_table FILE\n"
    "The figures ./lab bench recorded (the JSON lines ./lab bench --json wrote) as one table: bench, case,\n"
    "cpm, peer, ratio, target and whether it is met; then how many targets were met.\n";

int run(int argc, char** argv)
{
    const auto args = cpm::cli::parse_args(std::vector<std::string>(argv + 1, argv + argc), {}, "bench_table");
    if (args.positional.size() != 1) throw cpm::cli::UsageError("bench_table: give one FILE (see --help)");
    const std::string& file = args.positional[0];
    std::ifstream in(file);
    if (!in) {
        std::fprintf(stderr, "bench_table: cannot read %s\n", file.c_str());
        return 1;
    }
    std::printf("%-15s %-56s %12s %-10s %-44s %12s %7s %-26s %s\n", "bench", "case", "cpm", "unit", "peer", "peer value", "ratio", "target",
                "met");
    int line_no = 0, met = 0, missed = 0;
    for (std::string line; std::getline(in, line);) {
        ++line_no;
        if (line.empty()) continue;
        const auto f = nlohmann::json::parse(line, nullptr, false);
        if (f.is_discarded() || !f.is_object()) {
            std::fprintf(stderr, "bench_table: %s:%d: not a JSON object; skipped\n", file.c_str(), line_no);
            continue;
        }
        const std::string verdict = f.value("met", nlohmann::json()).is_boolean() ? (f["met"].get<bool>() ? "yes" : "NO") : "-";
        met += verdict == "yes";
        missed += verdict == "NO";
        std::printf("%-15s %-56s %12s %-10s %-44s %12s %7s %-26s %s\n", text(f.value("bench", nlohmann::json())).c_str(),
                    text(f.value("case", nlohmann::json())).c_str(), number(f.value("cpm", nlohmann::json())).c_str(),
                    text(f.value("unit", nlohmann::json())).c_str(), text(f.value("peer", nlohmann::json())).c_str(),
                    number(f.value("peer_value", nlohmann::json())).c_str(), number(f.value("ratio", nlohmann::json())).c_str(),
                    text(f.value("target", nlohmann::json())).c_str(), verdict.c_str());
    }
    std::printf("\ntargets met: %d, not met: %d\n", met, missed);
    return 0;
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "bench_table", kHelp, run); }
