// cpm fsm …: checking, converting and drawing state machines.
#include "Command.hpp"

#include <cpm/fsm/Loader.hpp>
#include <cpm/fsm/Render.hpp>

#include <cpm/ChildProcess.hpp>
#include <cpm/Error.hpp>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <stdexcept>
#include <unistd.h>

namespace cpm::tools {
namespace {

/// Graphviz's dot on `dot_text`, writing `out` (no shell: the name is passed as it is).
void run_dot(const std::string& dot_text, const std::string& format, const std::string& out)
{
    std::string dot;
    for (const char* dir : {"/usr/bin", "/usr/local/bin", "/bin"}) {
        if (dot.empty() && ::access((std::string(dir) + "/dot").c_str(), X_OK) == 0) dot = std::string(dir) + "/dot";
    }
    if (dot.empty()) throw cpm::Error("cannot run Graphviz's dot (install the Debian package graphviz)");
    char input[] = "/tmp/cpm_fsm_XXXXXX";
    const int fd = ::mkstemp(input);
    if (fd < 0) throw cpm::Error(std::string("cannot make a temporary file for dot: ") + std::strerror(errno));
    ::close(fd);
    std::ofstream(input) << dot_text;
    cpm::ChildProcess child({.argv = {dot, "-T" + format, "-o", out, input}});
    const auto end = child.wait(std::chrono::seconds(60));
    ::unlink(input);
    if (!end || !end->ok()) {
        throw cpm::Error("Graphviz's dot failed writing " + out + " (" + (end ? end->describe() : std::string("no end in 60 s")) + ")");
    }
}

const char* kFsmCheckHelp =
    "usage: cpm fsm check FILE.json\n"
    "\n"
    "Loads and checks a state machine as fsm_node would, and prints every error and warning with\n"
    "its file and JSON path. Exit code 0 when it has no errors (warnings allowed), 1 otherwise.\n"
    "The state and transition types and their parameters: fsm_node/README.md.\n";

const char* kFsmConvertHelp =
    "usage: cpm fsm convert FILE.uxf\n"
    "\n"
    "Prints the state machine of a UMLet drawing as JSON (the format fsm_node reads), after the\n"
    "same check as `cpm fsm check`; errors name the drawing's element. Exit code 1 on errors.\n";

const char* kFsmRenderHelp =
    "usage: cpm fsm render FILE.json|FILE.uxf -o|--output OUT.svg|OUT.png|OUT.dot\n"
    "\n"
    "Draws a checked state machine with Graphviz (`dot`, Debian package graphviz): states as\n"
    "boxes with id, type and parameters (the root bold, final states double-framed),\n"
    "transitions as arrows labelled with id, type and condition. Exit code 1 on errors.\n";

int fsm_check(const std::vector<std::string>& args)
{
    const std::string file = only_positional(parse_args(args, {}, "cpm fsm check"), "cpm fsm check", "machine file");
    auto result = cpm::fsm::load_file(file);
    for (const auto& e : result.errors) std::printf("error: %s\n", e.text().c_str());
    for (const auto& w : result.warnings) std::printf("warning: %s\n", w.text().c_str());
    if (!result.ok()) {
        std::printf("%s: %zu error(s), %zu warning(s)\n", file.c_str(), result.errors.size(), result.warnings.size());
        return 1;
    }
    std::printf("%s: ok (%zu states, %zu transitions, %zu warning(s))\n", file.c_str(), result.machine->states().size(),
                result.machine->transitions().size(), result.warnings.size());
    return 0;
}

int fsm_convert(const std::vector<std::string>& args)
{
    const std::string file = only_positional(parse_args(args, {}, "cpm fsm convert"), "cpm fsm convert", ".uxf file");
    auto checked = cpm::fsm::load_file(file);
    for (const auto& e : checked.errors) std::fprintf(stderr, "error: %s\n", e.text().c_str());
    for (const auto& w : checked.warnings) std::fprintf(stderr, "warning: %s\n", w.text().c_str());
    if (!checked.ok()) return 1;
    std::printf("%s\n", checked.json.c_str());
    return 0;
}

int fsm_render(const std::vector<std::string>& args)
{
    std::vector<std::string> spelled = args;
    for (auto& a : spelled) {
        if (a == "-o") a = "--output";  // the short form, as in dot and cc
    }
    const auto parsed = parse_args(spelled, {{"--output", true}}, "cpm fsm render");
    const std::string file = only_positional(parsed, "cpm fsm render", "machine file");
    const std::string out = parsed.get("--output");
    if (out.empty()) throw UsageError("cpm fsm render: -o OUT.svg|OUT.png|OUT.dot is required");
    const std::string format = out.substr(out.rfind('.') == std::string::npos ? out.size() : out.rfind('.') + 1);
    if (format != "svg" && format != "png" && format != "dot") {
        throw UsageError("cpm fsm render: -o " + out + ": the name must end in .svg, .png or .dot");
    }
    auto result = cpm::fsm::machine_to_dot(file);
    for (const auto& e : result.errors) std::fprintf(stderr, "error: %s\n", e.text().c_str());
    if (!result.errors.empty()) return 1;
    if (format == "dot") {
        std::ofstream(out) << result.dot;
    } else {
        run_dot(result.dot, format, out);
    }
    std::printf("%s: wrote %s\n", file.c_str(), out.c_str());
    return 0;
}

}  // namespace

std::vector<Command> fsm_commands()
{
    return {{.group = "fsm", .verb = "check", .summary = "check a state machine file (.json or UMLet .uxf): every error and warning", .help = kFsmCheckHelp, .run = fsm_check},
            {.group = "fsm", .verb = "convert", .summary = "print a UMLet drawing's state machine as JSON", .help = kFsmConvertHelp, .run = fsm_convert},
            {.group = "fsm", .verb = "render", .summary = "draw a state machine with Graphviz (-o OUT.svg|png|dot)", .help = kFsmRenderHelp, .run = fsm_render}};
}

std::string only_positional(const cpm::cli::ParsedArgs& parsed, const std::string& command, const std::string& what)
{
    if (parsed.positional.empty()) throw cpm::cli::UsageError(command + ": no " + what + " given (see --help)");
    if (parsed.positional.size() > 1) {
        throw cpm::cli::UsageError(command + ": unexpected argument '" + parsed.positional[1] + "'");
    }
    return parsed.positional[0];
}


}  // namespace cpm::tools
