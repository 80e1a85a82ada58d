// cpm_history: the lab's history service (KogMo-RTDB over DDS). Records every topic it
// discovers into a time-indexed store and answers historyRequest on historyReply.
#include <cpm/CommandLine.hpp>
#include <cpm/init.hpp>
#include <cpm/rtdb/ServiceCommand.hpp>

namespace {

const char* kHelp =
    "usage: cpm_history [--include REGEX]... [--exclude REGEX]... [--window 10s] [--topic-window TOPIC=DURATION]...\n"
    "                   [--max-bytes-total N] [--max-bytes-per-topic N] [--status-period 1s]\n"
    "                   [--record FILE [--record-format sqlite|mcap] [--foxglove-3d] [--record-max-bytes N] [--record-name NAME]]\n"
    "                   [--record-split 500MB|10min [--record-max 5GB]]\n"
    "                   [--save-dir DIR] [--save-on TOPIC[=FIELD==VALUE]]... [--save-before 30s] [--save-after 10s]\n"
    "                   [--save-format sqlite|mcap] [--simulated-clock] [--dds_domain N]\n"
    "\n"
    "Finds topics by DDS discovery and records every one whose name matches an --include pattern\n"
    "(all when none is given) and no --exclude pattern (full-match ECMAScript regexes), types it\n"
    "was never compiled with included: it keeps the serialized payloads and reads the stamps from\n"
    "the Header every cpm type starts with. Each topic keeps --window of history (--topic-window\n"
    "sets one topic's, e.g. --topic-window vehicleState=60s; repeatable) and at most\n"
    "--max-bytes-per-topic payload bytes (default 128 MiB), all topics together at most\n"
    "--max-bytes-total (default 512 MiB; --max-bytes is its older name). Deleted objects\n"
    "(disposed, or their writers gone) stay readable for the window.\n"
    "Answers historyRequest on historyReply (cpm history ..., cpm dump, cpm::HistoryClient) and\n"
    "publishes historyStatus every --status-period. Ends on SIGINT/SIGTERM.\n"
    "--record FILE: also writes every sample it ingests to FILE (a new file, never overwritten):\n"
    "SQLite, or MCAP for a FILE named *.mcap (or --record-format mcap), which Foxglove and every\n"
    "MCAP tool open (--foxglove-3d: the cars' poses also as foxglove::FrameTransform on /tf, for its\n"
    "3D panel). Either holds every object's info block and the IDL of cpm's types, kept whole beyond\n"
    "the window: cpm history --file FILE asks it the same questions, cpm play replays it. A writer\n"
    "thread batches the disk writes, so ingest never waits on the disk. --record-max-bytes N: the\n"
    "file stops growing at N bytes. A full disk (or that limit) ends the recording with an error\n"
    "naming the file; what was written stays readable and the live history goes on serving.\n"
    "The file is closed on SIGINT/SIGTERM; after a SIGKILL it still reads up to its last batch\n"
    "(SQLite) or its last chunk (MCAP: written at least once a second).\n"
    "--record-split SIZE|DURATION: a new file each time the current one reaches it (FILE's name\n"
    "with _000, _001, …; each file stands alone: the IDL, every living object and the newest\n"
    "sample of each transient-local topic again at its start); cpm history --file FOLDER reads\n"
    "them as one recording, none doubled. --record-max SIZE: the oldest files are deleted while\n"
    "all of them hold more.\n"
    "--save-dir DIR: where `cpm history save NAME` writes its recordings (the dash-cam: what the\n"
    "history holds of the last seconds and what comes in the next ones, into a new file NAME\n"
    "while the service goes on); default: the service's working directory.\n"
    "--save-on TOPIC[=FIELD==VALUE] (repeatable): a sample on TOPIC (with that field, by IDL path,\n"
    "equal to VALUE; != for unequal) saves by itself, from --save-before before it to --save-after\n"
    "after it, into save_<UTC time>_<topic>[_<key>].db (.mcap with --save-format mcap) in the save\n"
    "folder; e.g. --save-on stopRequest, --save-on fsmStatus=state_type==Emergency. With a filter,\n"
    "the sample with which an object begins to match fires (a state entered, not each sample in it).\n"
    "A trigger again while its save runs is within that save.\n"
    "--simulated-clock: joins the lab's simulated clock (as node cpm_history; cpm lab run does so in a\n"
    "simulated run) and holds it back, every 100 ms of lab time, until the recorder has received\n"
    "what every other node wrote before: a clock faster than the recorder (a busy machine, a paused\n"
    "process) waits instead of the recording losing samples. The service's own clock stays the wall clock.\n";

int run(int argc, char** argv)
{
    auto command = cpm::rtdb::read_service_flags(cpm::cli::parse_flags(argc, argv, cpm::rtdb::service_flags(), "cpm_history"));
    cpm::init(argc, argv);
    cpm::cli::stop_on_signals();
    return cpm::rtdb::serve(std::move(command), cpm::cli::stop_requested);
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "cpm_history", kHelp, run); }
