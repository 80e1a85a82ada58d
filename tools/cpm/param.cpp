// cpm param …: serving the lab's parameters.
#include "Command.hpp"

#include <cpm/ParameterServer.hpp>
#include <cpm/Participant.hpp>

#include <chrono>
#include <cstdio>
#include <thread>

namespace cpm::tools {
namespace {

const char* kParamHelp =
    "usage: cpm param serve FILE.json [--dds_domain N]\n"
    "\n"
    "Serves the file's parameters on topic 'parameter' and answers 'parameterRequest' until\n"
    "Ctrl-C. FILE: {\"name\": value, ...} with the type taken from the value, or\n"
    "{\"name\": {\"type\": \"bool|int|uint64|double|string|ints|doubles\", \"value\": ...}}.\n";

int param_serve(const std::vector<std::string>& args)
{
    const std::string file = only_positional(parse_args(args, {}, "cpm param serve"), "cpm param serve",
                                             "parameter file");
    cpm::cli::stop_on_signals();  // before it serves: a stop that comes at once still ends it cleanly
    cpm::Participant participant;
    cpm::ParameterServer server(participant);
    const size_t n = server.load_file(file);
    std::printf("serving %zu parameters from %s\n", n, file.c_str());
    std::fflush(stdout);
    while (!cpm::cli::stop_requested()) std::this_thread::sleep_for(std::chrono::milliseconds(50));
    return 0;
}

}  // namespace

std::vector<Command> param_commands()
{
    return {{.group = "param", .verb = "serve", .summary = "serve the parameters of a JSON file until Ctrl-C", .help = kParamHelp, .run = param_serve}};
}

}  // namespace cpm::tools
