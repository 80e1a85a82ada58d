// The service's request handling against an in-process store: answers, and malformed requests
// answered with an error that names the field and value.
#include <cpm/rtdb/HistoryJson.hpp>
#include <cpm/rtdb/Requests.hpp>

#include <ParameterPubSubTypes.h>
#include <VehicleStatePubSubTypes.h>

#include <gtest/gtest.h>

#include "serialized.hpp"

using namespace cpm::rtdb;

namespace {

struct AskFixture
{
    Store store;
    Oid oid = store.add_object({.topic = "vehicleState", .key = "3", .type_name = "VehicleState", .created_ts = 1});
    AskFixture()
    {
        for (uint64_t c : {100, 200, 300}) {
            const uint8_t b[] = {uint8_t(c / 100)};
            store.commit(oid, {c / 10, 0, 0, b, 1}, c);
        }
    }
    HistoryReply ask(const std::string& kind, uint64_t t0 = 0, uint64_t t1 = 0, uint32_t limit = 0)
    {
        HistoryRequest rq;
        rq.client_id("me");
        rq.request_id(7);
        rq.kind(kind);
        rq.topic("vehicleState");
        rq.key("3");
        rq.t0(t0);
        rq.t1(t1);
        rq.limit(limit);
        return answer(store, rq);
    }
};

TEST(HistoryRequests, AnswersCarryTheRequestIdsTheObjectAndTheSamples)
{
    AskFixture f;
    auto r = f.ask("at", 250);
    EXPECT_EQ(r.client_id(), "me");
    EXPECT_EQ(r.request_id(), 7u);
    EXPECT_EQ(r.status(), "ok");
    ASSERT_EQ(r.samples().size(), 1u);
    EXPECT_EQ(r.samples()[0].commit_ns(), 200u);
    EXPECT_EQ(r.samples()[0].data_ns(), 20u);
    EXPECT_EQ(r.samples()[0].payload(), std::vector<uint8_t>{2});
    ASSERT_EQ(r.objects().size(), 1u);
    EXPECT_EQ(r.objects()[0].name(), "vehicleState/3");
    EXPECT_EQ(r.objects()[0].samples_held(), 3u);
    EXPECT_EQ(f.ask("range", 100, 300).samples().size(), 2u);
    EXPECT_EQ(f.ask("younger", 300).status(), "not_yet");
    EXPECT_EQ(f.ask("older", 100).status(), "not_found");
}

TEST(HistoryRequests, MalformedRequestsGetAnErrorNamingWhatIsWrong)
{
    AskFixture f;
    auto bad_kind = f.ask("teleport");
    EXPECT_EQ(bad_kind.status(), "error");
    EXPECT_NE(bad_kind.error().find("unknown kind 'teleport'"), std::string::npos) << bad_kind.error();
    auto backwards = f.ask("range", 300, 100);
    EXPECT_EQ(backwards.status(), "error");
    EXPECT_EQ(backwards.error(), "range: t1 (100) is before t0 (300)");
    auto absurd = f.ask("range", 0, 1000, 5'000'000);
    EXPECT_EQ(absurd.status(), "error");
    EXPECT_EQ(absurd.error(), "limit 5000000 is above 100000");

    HistoryRequest rq;
    rq.kind("latest");
    rq.topic("vehicleState");
    rq.key("9");
    auto unknown = answer(f.store, rq);
    EXPECT_EQ(unknown.status(), "unknown_object");
    EXPECT_NE(unknown.error().find("no object 'vehicleState/9'"), std::string::npos) << unknown.error();
    // A keyed topic asked without its key: its keys, not "never recorded".
    f.store.add_object({.topic = "vehicleState", .key = "12", .type_name = "VehicleState", .created_ts = 1});
    rq.key("");
    const auto keyless = answer(f.store, rq);
    EXPECT_EQ(keyless.status(), "unknown_object");
    EXPECT_EQ(keyless.error(), "topic 'vehicleState' is keyed: ask for one key (--key K), one of 12, 3");
    rq.key("9");
    rq.kind("search");
    rq.name_regex("(open");
    auto regex = answer(f.store, rq);
    EXPECT_EQ(regex.status(), "error");
    EXPECT_NE(regex.error().find("name_regex '(open' is not a regular expression"), std::string::npos) << regex.error();
    rq.kind("at");
    rq.name_regex("");
    rq.by("sideways");
    EXPECT_EQ(answer(f.store, rq).error(), "by is 'sideways'; expected commit or data");
    rq.by("");
    rq.kind("wait_next");
    rq.timeout_ns(3'600'000'000'000ull);
    EXPECT_EQ(answer(f.store, rq).error(), "timeout_ns 3600000000000 is above 60 s");
    rq.timeout_ns(0);
    rq.kind("snapshot");
    rq.t0(250);
    EXPECT_EQ(answer(f.store, rq).status(), "error");
    EXPECT_EQ(answer(f.store, rq).error(), "snapshot: objects is empty");
    rq.objects({"vehicleState/3", "noSuchTopic"});
    const auto unknown_member = answer(f.store, rq);
    EXPECT_EQ(unknown_member.status(), "unknown_object");
    EXPECT_NE(unknown_member.error().find("no object 'noSuchTopic'"), std::string::npos) << unknown_member.error();
    EXPECT_EQ(f.ask("latest").status(), "ok");  // and it still answers
}

TEST(HistoryRequests, SnapshotAnswersEachObjectWithItsOwnStatus)
{
    AskFixture f;
    f.store.add_object({.topic = "rangeSensors", .key = "3"});
    HistoryRequest rq;
    rq.kind("snapshot");
    rq.objects({"vehicleState/3", "rangeSensors/3"});
    rq.t0(250);
    auto r = answer(f.store, rq);
    EXPECT_EQ(r.status(), "partial");
    ASSERT_EQ(r.samples().size(), 2u);
    EXPECT_EQ(r.samples()[0].status(), "ok");
    EXPECT_EQ(r.samples()[0].commit_ns(), 200u);
    EXPECT_EQ(r.samples()[1].status(), "not_found");
    EXPECT_EQ(r.objects()[1].name(), "rangeSensors/3");
}

// A writer that was restarted after its old self was marked dead (its lease ran out first)
// gives its topic and key a new object; the old one stays held for the window. A question by
// name about a time before the restart is answered from the old object, not "not_found"
// because the newest object began later; one about later times from the new one.
TEST(HistoryRequests, QuestionsByNameAcrossAWriterRestartAreAnsweredFromTheObjectOfThatTime)
{
    AskFixture f;  // the first writer's samples committed at 100, 200, 300
    f.store.mark_deleted(f.oid, 350);
    const Oid again = f.store.add_object({.topic = "vehicleState", .key = "3", .type_name = "VehicleState", .created_ts = 400});
    for (uint64_t c : {500, 600}) {
        const uint8_t b[] = {uint8_t(c / 100)};
        f.store.commit(again, {c / 10, 0, 0, b, 1}, c);
    }
    auto payload = [](const HistoryReply& r) { return r.samples().empty() ? -1 : int(r.samples()[0].payload().at(0)); };
    const auto before = f.ask("at", 250);
    EXPECT_EQ(before.status(), "ok");
    EXPECT_EQ(payload(before), 2);
    ASSERT_EQ(before.objects().size(), 1u);
    EXPECT_EQ(before.objects()[0].oid(), f.oid) << "the object that held the sample then";
    EXPECT_NE(before.objects()[0].deleted_ts(), 0u);
    EXPECT_EQ(payload(f.ask("at", 450)), 3) << "between the two: the old writer's last";
    EXPECT_EQ(payload(f.ask("older", 500)), 3);
    EXPECT_EQ(payload(f.ask("at", 550)), 5);
    EXPECT_EQ(f.ask("at", 550).objects()[0].oid(), again);
    EXPECT_EQ(payload(f.ask("latest")), 6);
    EXPECT_EQ(payload(f.ask("younger", 150)), 2) << "the next one after 150 is the old writer's";
    EXPECT_EQ(payload(f.ask("younger", 350)), 5);
    EXPECT_EQ(f.ask("older", 100).status(), "not_found");
    EXPECT_EQ(f.ask("younger", 600).status(), "not_yet");
    // A range across the restart: both writers' samples, in order.
    const auto span = f.ask("range", 150, 650);
    EXPECT_EQ(span.status(), "ok");
    std::vector<int> got;
    for (const auto& s : span.samples()) got.push_back(s.payload().at(0));
    EXPECT_EQ(got, (std::vector<int>{2, 3, 5, 6}));
    EXPECT_EQ(f.ask("range", 150, 650, 3).samples().size(), 3u);
    EXPECT_TRUE(f.ask("range", 150, 650, 3).truncated());
    EXPECT_TRUE(f.ask("range", 150, 650, 2).truncated()) << "the old writer's two, and the new one's after them left out";
    EXPECT_FALSE(f.ask("range", 150, 450, 2).truncated());
    EXPECT_EQ(f.ask("range", 150, 450, 2).objects().size(), 1u) << "only the object the samples came from";
    // A snapshot takes each name's object of that time.
    HistoryRequest rq;
    rq.kind("snapshot");
    rq.objects({"vehicleState/3"});
    rq.t0(250);
    const auto cut = answer(f.store, rq);
    EXPECT_EQ(cut.status(), "ok");
    ASSERT_EQ(cut.samples().size(), 1u);
    EXPECT_EQ(int(cut.samples()[0].payload().at(0)), 2);
}

}  // namespace

// The client's calls over a backend other than the DDS service: the same typed answers and
// statuses, from a store in this process.
TEST(HistoryRequests, AClientAnswersFromAStoreThroughItsBackend)
{
    Store store;
    const Oid oid = store.add_object({.topic = "vehicleState", .key = "3", .type_name = "VehicleState", .created_ts = 1});
    for (uint64_t c : {100, 200, 300}) {
        VehicleState s;
        s.vehicle_id(3);
        s.speed(double(c) / 100);
        s.header().create_stamp().nanoseconds(c - 50);
        const std::vector<uint8_t> bytes = serialized<VehicleStatePubSubType>(s);
        store.commit(oid, {c - 50, c - 40, c, bytes.data(), bytes.size()}, c);
    }
    cpm::HistoryClient client(std::make_unique<StoreBackend>(store));

    auto at = client.at<VehicleState>("vehicleState", 3, 250);
    ASSERT_TRUE(at.ok()) << at.status << " " << at.error;
    EXPECT_EQ(at.commit_ns, 200u);
    EXPECT_EQ(at.data_ns, 150u);
    EXPECT_DOUBLE_EQ(at.sample.speed(), 2.0);
    auto by_data = client.at<VehicleState>("vehicleState", 3, 255, cpm::HistoryBy::data);
    ASSERT_TRUE(by_data.ok());
    EXPECT_DOUBLE_EQ(by_data.sample.speed(), 3.0);  // data time 250 <= 255

    EXPECT_EQ(client.younger<VehicleState>("vehicleState", 3, 300).status, cpm::history::Status::not_yet);
    EXPECT_EQ(client.older<VehicleState>("vehicleState", 3, 100).status, cpm::history::Status::not_found);
    auto unknown = client.latest<VehicleState>("vehicleState", 9);
    EXPECT_EQ(unknown.status, cpm::history::Status::unknown_object);
    EXPECT_NE(unknown.error.find("vehicleState/9"), std::string::npos) << unknown.error;
    auto range = client.range<VehicleState>("vehicleState", 3, 100, 300);
    ASSERT_EQ(range.size(), 2u);
    EXPECT_DOUBLE_EQ(range[1].sample.speed(), 2.0);
    auto whole = client.range_of<VehicleState>("vehicleState", 3, 100, 301);
    EXPECT_TRUE(whole.complete()) << whole.status;
    auto cut = client.range_of<VehicleState>("vehicleState", 3, 100, 301, cpm::HistoryBy::commit, 2);
    EXPECT_TRUE(cut.truncated);
    EXPECT_FALSE(cut.complete());
    EXPECT_EQ(cut.samples.size(), 2u);
    // The oldest evicted: a span reaching back to it says it is partial, with what is held.
    store.expire(100 + Retention{}.window_ns + 1);
    auto partial = client.range_of<VehicleState>("vehicleState", 3, 0, 301);
    EXPECT_EQ(partial.status, cpm::history::Status::partial);
    EXPECT_FALSE(partial.complete());
    ASSERT_EQ(partial.samples.size(), 2u);
    EXPECT_TRUE(partial.samples[0].ok()) << "each sample held is itself ok";
    // A payload that is not the type asked for is an error, not a zeroed sample.
    auto wrong = client.latest<Parameter>("vehicleState", 3);
    EXPECT_EQ(wrong.status, cpm::history::Status::error);
}

TEST(HistoryVocabulary, EverySpellingReadsBackAsItself)
{
    for (auto s : cpm::history::kAllStatuses) EXPECT_EQ(cpm::history::status_from(cpm::history::to_string(s)), s);
    for (auto k : cpm::history::kAllKinds) EXPECT_EQ(cpm::history::kind_from(cpm::history::to_string(k)), k);
    EXPECT_EQ(cpm::history::status_from("not found"), std::nullopt);  // DESIGN's spelling only
    EXPECT_EQ(cpm::history::by_from(""), cpm::history::By::commit);
    EXPECT_EQ(cpm::history::by_from("Data"), std::nullopt);
    EXPECT_EQ(cpm::history::to_string(cpm::history::Status::not_yet), "not_yet");
}

TEST(HistoryJson, ObjectsAndSamplesAreWrittenAsDesignSaysAndOidsReadBack)
{
    Store store;
    const Oid oid = store.add_object({.topic = "vehicleState", .key = "3", .type_name = "VehicleState", .created_ts = 1000});
    VehicleState s;
    s.vehicle_id(3);
    s.speed(1.25);
    const auto bytes = serialized<VehicleStatePubSubType>(s);
    store.commit(oid, {10, 20, 30, bytes.data(), bytes.size()}, 2000);
    HistoryRequest rq;
    rq.kind("latest");
    rq.topic("vehicleState");
    rq.key("3");
    const auto reply = answer(store, rq);
    ASSERT_EQ(reply.objects().size(), 1u);
    const auto object = object_json(reply.objects()[0], 3000);
    EXPECT_EQ(object["name"], "vehicleState/3");
    EXPECT_EQ(object["created_ns"], 1000u);
    EXPECT_EQ(object["deleted_ns"], 0u);
    EXPECT_FALSE(object.contains("created_ts"));
    const auto* types = IdlDecoder::lab_types();
    ASSERT_NE(types, nullptr);
    const auto sample = sample_json(reply.samples()[0], &reply.objects()[0], types);
    EXPECT_EQ(sample["status"], "ok");
    EXPECT_EQ(sample["commit_ns"], 2000u);
    EXPECT_EQ(sample["data_ns"], 10u);
    EXPECT_EQ(sample["data"]["speed"], 1.25);
    EXPECT_EQ(sample["data"]["vehicle_id"], 3);
    const auto unknown = sample_json(reply.samples()[0], nullptr, nullptr);
    EXPECT_EQ(unknown["payload_base64"], base64(bytes));

    EXPECT_EQ(oid_text(7), "7");
    EXPECT_EQ(oid_text(2ull << 32 | 7), "7.2");
    EXPECT_EQ(oid_from_text("7.2"), 2ull << 32 | 7);
    EXPECT_EQ(oid_from_text(oid_text(oid)), oid);
    for (const char* bad : {"", "0", "x", "7.", ".2", "7.2.1", "-3", "99999999999.1"}) EXPECT_EQ(oid_from_text(bad), std::nullopt) << bad;
}
