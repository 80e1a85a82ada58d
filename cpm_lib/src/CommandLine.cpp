#include <cpm/CommandLine.hpp>
#include <cpm/init.hpp>

#include <cmath>
#include <csignal>
#include <cstdio>
#include <sstream>

namespace cpm::cli {

std::string ParsedArgs::get(const std::string& name, const std::string& fallback) const
{
    auto it = flags.find(name);
    return it == flags.end() ? fallback : it->second;
}

std::vector<std::string> ParsedArgs::all(const std::string& name) const
{
    std::vector<std::string> values;
    auto it = flags.find(name);
    if (it == flags.end()) return values;
    std::istringstream joined(it->second);
    for (std::string v; std::getline(joined, v);) values.push_back(v);
    return values;
}

ParsedArgs parse_args(const std::vector<std::string>& args, const std::vector<FlagSpec>& known,
                      const std::string& command)
{
    ParsedArgs parsed;
    for (size_t i = 0; i < args.size(); ++i) {
        std::string name = args[i], value;
        if (name.rfind("--", 0) != 0) {
            parsed.positional.push_back(name);
            continue;
        }
        const auto eq = name.find('=');
        if (eq != std::string::npos) {
            value = name.substr(eq + 1);
            name = name.substr(0, eq);
        }
        bool takes_value = false;
        if (is_init_flag(name, takes_value)) {
            parsed.init_args.push_back(args[i]);
            if (takes_value && eq == std::string::npos && i + 1 < args.size()) parsed.init_args.push_back(args[++i]);
            continue;
        }
        const FlagSpec* spec = nullptr;
        for (const auto& k : known) {
            if (name == k.name) spec = &k;
        }
        if (spec == nullptr) throw UsageError(command + ": unknown flag '" + name + "' (see --help)");
        if (!spec->takes_value) {
            parsed.flags[name] = "1";
            continue;
        }
        if (eq == std::string::npos) {
            if (i + 1 >= args.size()) throw UsageError(command + ": " + name + " needs a value");
            value = args[++i];
        }
        auto [it, inserted] = parsed.flags.emplace(name, value);
        if (!inserted) {
            if (!spec->repeatable) throw UsageError(command + ": " + name + " given twice");
            it->second += "\n" + value;
        }
    }
    return parsed;
}

bool wants_help(const std::vector<std::string>& args)
{
    for (const auto& a : args) {
        if (a == "--help" || a == "-h") return true;
    }
    return false;
}

uint64_t parse_duration(const std::string& flag, const std::string& text)
{
    static const std::map<std::string, uint64_t> units{
        {"ns", 1}, {"us", 1'000}, {"ms", 1'000'000}, {"s", 1'000'000'000}, {"m", 60'000'000'000}, {"h", 3'600'000'000'000}};
    size_t end = 0;
    double value = 0;
    try {
        value = std::stod(text, &end);
    } catch (const std::exception&) {
        end = 0;
    }
    const auto unit = units.find(text.substr(end));
    if (end == 0 || unit == units.end() || !(value >= 0)) {
        throw UsageError(flag + ": '" + text + "' is not a duration (a number with ns, us, ms, s, m or h, e.g. 10s)");
    }
    return static_cast<uint64_t>(value * double(unit->second));
}

double parse_number(const std::string& flag, const std::string& text, double min, double max)
{
    size_t end = 0;
    double value = NAN;
    try {
        value = std::stod(text, &end);
    } catch (const std::exception&) {
        end = 0;
    }
    if (end == 0 || end != text.size() || !(value >= min && value <= max)) {
        std::ostringstream range;
        range << min << ".." << max;
        throw UsageError(flag + ": '" + text + "' is not a number in " + range.str());
    }
    return value;
}

long long parse_integer(const std::string& flag, const std::string& text, long long min, long long max)
{
    size_t end = 0;
    long long value = 0;
    try {
        value = std::stoll(text, &end);
    } catch (const std::exception&) {
        end = 0;
    }
    if (end == 0 || end != text.size() || value < min || value > max) {
        throw UsageError(flag + ": '" + text + "' is not a whole number in " + std::to_string(min) + ".." +
                         std::to_string(max));
    }
    return value;
}

std::vector<std::string> split_list(const std::string& flag, const std::string& text)
{
    std::vector<std::string> items;
    std::stringstream in(text);
    for (std::string item; std::getline(in, item, ',');) {
        if (item.empty()) throw UsageError(flag + ": empty item in '" + text + "'");
        items.push_back(item);
    }
    if (items.empty()) throw UsageError(flag + ": nothing given");
    return items;
}

namespace {
volatile std::sig_atomic_t g_stop_requested = 0;
}  // namespace

void stop_on_signals()
{
    std::signal(SIGINT, [](int) { g_stop_requested = 1; });
    std::signal(SIGTERM, [](int) { g_stop_requested = 1; });
}

bool stop_requested() { return g_stop_requested != 0; }

int run_main(int argc, char** argv, const char* program, const char* help, const std::function<int(int, char**)>& run)
{
    if (wants_help(std::vector<std::string>(argv + 1, argv + argc))) {
        std::fputs(help, stdout);
        return 0;
    }
    // The program's name once, whether or not the message already starts with it.
    auto report = [program](const char* what) {
        const std::string prefix = std::string(program) + ": ";
        std::fprintf(stderr, "%s%s\n", std::string(what).rfind(prefix, 0) == 0 ? "" : prefix.c_str(), what);
    };
    try {
        return run(argc, argv);
    } catch (const UsageError& e) {
        report(e.what());
        return kUsageExit;
    } catch (const std::exception& e) {
        report(e.what());
        return 1;
    }
}

}  // namespace cpm::cli
