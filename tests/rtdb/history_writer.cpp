// A writer process for the history service's end-to-end tests.
//   history_writer --type vehicle|lab_only|tiny --topic T --vehicle K --count N [--dispose] [--stay]
// Waits for a reader (the service), writes N samples with data times kBase + k ms
// (valid_after = data + 5 ns; VehicleState pose.x = k; LabOnlyThing note "thing k", value k/2),
// waits for them to be acknowledged and prints "written N". --dispose then disposes the
// instance ("disposed"); --stay keeps the process alive until it is killed.
#include <cpm/CommandLine.hpp>
#include <cpm/Participant.hpp>
#include <cpm/init.hpp>

#include <LabOnlyThingPubSubTypes.h>
#include <TinyPubSubTypes.h>
#include <VehicleStatePubSubTypes.h>

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/topic/Topic.hpp>

#include <chrono>
#include <cstdio>
#include <string>
#include <thread>

namespace fdds = eprosima::fastdds::dds;

constexpr uint64_t kBase = 1'700'000'000'000'000'000ull;

namespace {

const char* kHelp =
    "usage: history_writer [--type vehicle|lab_only|tiny] [--topic T] [--vehicle K] [--count N] [--readers N] [--dispose] [--stay]\n"
    "Waits for a reader, writes N samples (default 10) of the type on T (default vehicleState) as vehicle K\n"
    "(default 3), waits for them to be acknowledged and prints \"written N\"; --dispose then disposes the\n"
    "instance, --stay keeps the process alive until it is killed.\n";

int run(int argc, char** argv)
{
    const auto flags = cpm::cli::parse_flags(argc, argv,
                                             {{"--type", true}, {"--topic", true}, {"--vehicle", true}, {"--count", true},
                                              {"--dispose", false}, {"--stay", false}, {"--readers", true}},
                                             "history_writer");
    const std::string type = flags.get("--type", "vehicle"), topic = flags.get("--topic", "vehicleState");
    if (type != "vehicle" && type != "lab_only" && type != "tiny")
        throw cpm::cli::UsageError("history_writer: --type '" + type + "' is none of vehicle, lab_only, tiny");
    const int vehicle = int(cpm::cli::parse_integer("--vehicle", flags.get("--vehicle", "3"), 0, 255));
    const int count = int(cpm::cli::parse_integer("--count", flags.get("--count", "10"), 0, 1'000'000));
    const bool dispose = flags.has("--dispose"), stay = flags.has("--stay");
    const int readers = int(cpm::cli::parse_integer("--readers", flags.get("--readers", "1"), 1, 100));
    cpm::init(argc, argv);
    cpm::ParticipantOptions options = cpm::ParticipantOptions::from_init();
    options.name = "history_writer_" + type;
    options.shared_memory = false;  // see HistoryServiceEndToEndTest: no reuse of a dead process's shared-memory port
    cpm::Participant participant(options);
    auto* p = participant.native();
    fdds::TypeSupport support(type == "vehicle" ? static_cast<fdds::TopicDataType*>(new VehicleStatePubSubType)
                             : type == "lab_only" ? static_cast<fdds::TopicDataType*>(new LabOnlyThingPubSubType)
                                                  : static_cast<fdds::TopicDataType*>(new TinyPubSubType));
    support->auto_fill_type_information(false);
    support->auto_fill_type_object(false);
    support.register_type(p);
    auto* t = p->create_topic(topic, support.get_type_name(), fdds::TOPIC_QOS_DEFAULT);
    auto* publisher = p->create_publisher(fdds::PUBLISHER_QOS_DEFAULT);
    fdds::DataWriterQos qos = fdds::DATAWRITER_QOS_DEFAULT;
    qos.reliability().kind = fdds::RELIABLE_RELIABILITY_QOS;
    qos.durability().kind = fdds::TRANSIENT_LOCAL_DURABILITY_QOS;
    qos.history().kind = fdds::KEEP_LAST_HISTORY_QOS;
    qos.history().depth = std::max(count, 1);
    qos.data_sharing().off();
    // As cpm's writers do: with Fast DDS's 3 s heartbeat a dispose (sent without one) is
    // acknowledged only at the next periodic heartbeat.
    qos.reliable_writer_qos().times.heartbeatPeriod = {0, 100'000'000};
    auto* writer = publisher->create_datawriter(t, qos);
    if (!writer) return 2;
    fdds::PublicationMatchedStatus matched{};
    for (int waited = 0; matched.current_count < readers; waited += 10) {
        if (waited > 20000) {
            std::fprintf(stderr, "history_writer: no reader matched\n");
            return 3;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
        writer->get_publication_matched_status(matched);
    }
    VehicleState vs;
    LabOnlyThing thing;
    Tiny tiny;
    for (int k = 0; k < count; ++k) {
        const uint64_t data = kBase + uint64_t(k) * 1'000'000;
        void* sample = &tiny;
        if (type == "vehicle") {
            vs.vehicle_id(uint8_t(vehicle));
            vs.header().create_stamp().nanoseconds(data);
            vs.header().valid_after_stamp().nanoseconds(data + 5);
            vs.pose().x(k);
            sample = &vs;
        } else if (type == "lab_only") {
            thing.vehicle_id(uint8_t(vehicle));
            thing.header().create_stamp().nanoseconds(data);
            thing.header().valid_after_stamp().nanoseconds(data + 5);
            thing.note("thing " + std::to_string(k));
            thing.value(k * 0.5);
            sample = &thing;
        } else {
            tiny.a(uint8_t(k));
        }
        if (!writer->write(sample)) return 4;
        std::this_thread::sleep_for(std::chrono::milliseconds(2));  // distinct commit times, a realistic pace
    }
    if (writer->wait_for_acknowledgments({10, 0}) != ReturnCode_t::RETCODE_OK) {
        writer->get_publication_matched_status(matched);
        std::fprintf(stderr, "history_writer: %d samples not acknowledged within 10 s by %d matched readers\n", count,
                     matched.current_count);
        return 5;
    }
    std::printf("written %d\n", count);
    std::fflush(stdout);
    if (dispose) {
        void* sample = type == "vehicle" ? static_cast<void*>(&vs) : static_cast<void*>(&thing);
        writer->dispose(sample, fdds::HANDLE_NIL);
        if (writer->wait_for_acknowledgments({10, 0}) != ReturnCode_t::RETCODE_OK) {
            std::fprintf(stderr, "history_writer: the dispose was not acknowledged within 10 s\n");
            return 6;
        }
        std::printf("disposed\n");
        std::fflush(stdout);
    }
    while (stay) std::this_thread::sleep_for(std::chrono::seconds(1));
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    return 0;
}

}  // namespace

int main(int argc, char** argv) { return cpm::cli::run_main(argc, argv, "history_writer", kHelp, run); }
