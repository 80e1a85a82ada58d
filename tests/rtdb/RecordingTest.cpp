// A recording written through the IngestSink interface as the service writes it, then read
// back: every question answers as it did from the store the samples went to; bad files, a
// full disk and damage give an error naming the file and keep what was written.
#include <cpm/Error.hpp>
#include <cpm/rtdb/HistoryJson.hpp>
#include <cpm/rtdb/Recording.hpp>
#include <cpm/rtdb/Requests.hpp>

#include <cpm_test/Isolation.hpp>
#include <cpm_test/TempDir.hpp>

#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <thread>

using namespace cpm::rtdb;
namespace fs = std::filesystem;

using cpm_test::TempDir;

namespace {


/// A store and a recording fed the same way the service's outlet feeds them.
struct Lab
{
    Store store;
    RecordingWriter writer;
    explicit Lab(const std::string& path, RecordingOptions o = {}) : writer(path, o) {}
    Oid add(ObjectInfo info)
    {
        const Oid oid = store.add_object(std::move(info));
        writer.object_added(*store.info(oid));
        return oid;
    }
    uint64_t commit(Oid oid, uint64_t data_ns, const std::vector<uint8_t>& payload, uint64_t now, uint64_t lost_before = 0)
    {
        Incoming in{data_ns, data_ns + 60, now - 5, payload.data(), payload.size(), lost_before};
        const uint64_t c = store.commit(oid, in, now);
        writer.sample_committed(oid, in, c);
        return c;
    }
    void remove(Oid oid, uint64_t t)
    {
        store.mark_deleted(oid, t);
        writer.object_deleted(oid, t);
    }
};

HistoryRequest request(const std::string& kind, const std::string& topic, const std::string& key, uint64_t t0, uint64_t t1 = 0,
                       const std::string& by = "commit")
{
    HistoryRequest rq;
    rq.client_id("test");
    rq.kind(kind);
    rq.topic(topic);
    rq.key(key);
    rq.t0(t0);
    rq.t1(t1);
    rq.by(by);
    return rq;
}

/// A reply as text: every sample with its times and payload, every object's info block.
std::string text(const HistoryReply& r)
{
    std::string out = r.status() + " " + r.error() + (r.truncated() ? " truncated" : "") + " lost=" + std::to_string(r.lost()) + "\n";
    for (const auto& o : r.objects()) out += object_json(o, 0).dump() + "\n";
    for (const auto& s : r.samples()) out += sample_json(s, nullptr, nullptr).dump() + "\n";
    return out;
}

}  // namespace

TEST(Recording, AnswersEveryQueryAsTheStoreItRecorded)
{
    for (const std::string format : {"db", "mcap"}) {
        SCOPED_TRACE("a recording in " + format);
        TempDir dir;
        const std::string path = dir.file("recording." + format);
        std::vector<HistoryRequest> questions;
        std::vector<std::string> live;
        {
            Lab lab(path, {.name = "unit"});
            const Oid proc = lab.add({.kind = ObjectKind::process, .name = "fsm_node_5", .type_name = "participant", .created_ts = 900});
            const Oid car = lab.add({.topic = "vehicleState", .key = "5", .type_name = "VehicleState", .parent = proc, .creator = "fsm_node_5",
                                     .created_ts = 1000});
            const Oid other = lab.add({.topic = "vehicleState", .key = "6", .type_name = "VehicleState", .created_ts = 1000});
            const Oid gone = lab.add({.topic = "log", .type_name = "Log", .created_ts = 1100});
            std::mt19937 rng(7);
            for (uint64_t i = 0; i < 400; ++i) {
                std::vector<uint8_t> payload(8 + rng() % 64);
                for (auto& b : payload) b = uint8_t(rng());
                const uint64_t now = 2000 + i * 10;
                // Data times out of order now and then; a tie in commit time; a gap of lost samples.
                lab.commit(car, now - (i % 7 == 3 ? 40 : 2), payload, i == 50 ? 2000 + 49 * 10 : now, i == 120 ? 3 : 0);
                if (i % 3 == 0) lab.commit(other, now - 1, payload, now + 1);
                if (i < 20) lab.commit(gone, now, payload, now + 2);
            }
            lab.remove(gone, 2500);
            lab.writer.close();
            EXPECT_EQ(lab.writer.counters().written, 400u + 134u + 20u);
            EXPECT_EQ(lab.writer.counters().dropped, 0u);
            for (const std::string by : {"commit", "data"}) {
                for (uint64_t t : {0ull, 1999ull, 2000ull, 2005ull, 2490ull, 2491ull, 3000ull, 5990ull, 6000ull, 9000ull}) {
                    for (const std::string kind : {"at", "older", "younger"}) {
                        for (const std::string key : {"5", "6"}) questions.push_back(request(kind, "vehicleState", key, t, 0, by));
                        questions.push_back(request(kind, "log", "", t, 0, by));
                    }
                }
                questions.push_back(request("range", "vehicleState", "5", 2100, 3300, by));
                questions.push_back(request("range", "log", "", 0, 10000, by));
            }
            questions.push_back(request("latest", "vehicleState", "5", 0));
            questions.push_back(request("successor", "vehicleState", "5", 3180));  // the gap before i == 120
            questions.push_back(request("successor", "vehicleState", "5", 3000));
            auto snap = request("snapshot", "", "", 2500);
            snap.objects({"vehicleState/5", "vehicleState/6", "log"});
            questions.push_back(snap);
            questions.push_back(request("list", "", "", 0));
            auto search = request("search", "", "", 0);
            search.name_regex("VEHICLE");
            questions.push_back(search);
            auto alive = request("search", "", "", 0);
            alive.alive_at(2600);
            questions.push_back(alive);
            for (const auto& q : questions) live.push_back(text(answer(lab.store, q)));
        }
        const LoadedRecording rec = load_recording(path);
        EXPECT_TRUE(rec.complete) << rec.warning;
        EXPECT_EQ(rec.warning, "");
        EXPECT_EQ(rec.name, "unit");
        EXPECT_EQ(rec.samples, 554u);
        ASSERT_TRUE(rec.types) << "the recording carries the IDL of cpm's types";
        EXPECT_TRUE(rec.types->knows("VehicleState"));
        for (size_t i = 0; i < questions.size(); ++i) {
            EXPECT_EQ(text(answer(*rec.store, questions[i])), live[i]) << "question " << i << ": " << questions[i].kind() << " "
                                                                       << questions[i].topic() << "/" << questions[i].key() << " t0=" << questions[i].t0()
                                                                       << " by " << questions[i].by();
        }
    }
}

TEST(Recording, AClientOpensARecordingAndAnswersTypedCalls)
{
    TempDir dir;
    const std::string path = dir.file("r.db");
    {
        Lab lab(path);
        const Oid o = lab.add({.topic = "numbers", .type_name = "Unknown", .created_ts = 1});
        for (uint8_t i = 1; i <= 5; ++i) lab.commit(o, 100 * i, {i, i, i}, 1000 * i);
    }
    auto client = cpm::HistoryClient::open_recording(path);
    auto r = client.request(request("at", "numbers", "", 3500));
    ASSERT_EQ(r.status(), "ok");
    ASSERT_EQ(r.samples().size(), 1u);
    EXPECT_EQ(r.samples()[0].commit_ns(), 3000u);
    EXPECT_EQ(r.samples()[0].payload(), (std::vector<uint8_t>{3, 3, 3}));
    // A finished run gets nothing new: a wait answers at once.
    auto w = request("wait_next", "numbers", "", 5000);
    w.timeout_ns(30'000'000'000ull);
    const auto t0 = std::chrono::steady_clock::now();
    EXPECT_EQ(client.request(w).status(), "timeout");
    EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(5));
}

TEST(Recording, NeverOverwritesAFileAndNamesIt)
{
    TempDir dir;
    const std::string path = dir.file("exists.db");
    std::ofstream(path) << "precious";
    try {
        RecordingWriter w(path);
        FAIL() << "a recording overwrote " << path;
    } catch (const cpm::Error& e) {
        EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("exists"), std::string::npos) << e.what();
    }
    std::ifstream in(path);
    std::string content;
    in >> content;
    EXPECT_EQ(content, "precious");
    try {
        RecordingWriter w(dir.file("no/such/folder/r.db"));
        FAIL() << "a recording in a missing folder";
    } catch (const cpm::Error& e) {
        EXPECT_NE(std::string(e.what()).find("no/such/folder/r.db"), std::string::npos) << e.what();
    }
}

TEST(Recording, AFileThatIsNoRecordingIsNamedInTheError)
{
    TempDir dir;
    for (const auto& [name, content] : std::vector<std::pair<std::string, std::string>>{{"text.db", "hello, not sqlite at all\n"}, {"empty.db", ""}}) {
        std::ofstream(dir.file(name)) << content;
        try {
            (void)load_recording(dir.file(name));
            FAIL() << name << " loaded as a recording";
        } catch (const cpm::Error& e) {
            EXPECT_NE(std::string(e.what()).find(dir.file(name)), std::string::npos) << e.what();
        }
    }
    try {
        (void)load_recording(dir.file("missing.db"));
        FAIL();
    } catch (const cpm::Error& e) {
        EXPECT_NE(std::string(e.what()).find("no such file"), std::string::npos) << e.what();
    }
    EXPECT_THROW((void)cpm::HistoryClient::open_recording(dir.file("text.db")), cpm::Error);
}

TEST(Recording, AFullDiskStopsTheRecordingWithAnErrorAndKeepsWhatWasWritten)
{
    for (const std::string format : {"db", "mcap"}) {
        SCOPED_TRACE("a recording in " + format);
        TempDir dir;
        const std::string path = dir.file("full." + format);
        Lab lab(path, {.max_bytes = 256 * 1024, .flush_period_ns = 1'000'000});
        const Oid o = lab.add({.topic = "big", .type_name = "Blob", .created_ts = 1});
        const std::vector<uint8_t> payload(1000, 0xab);
        uint64_t now = 1000;
        for (int i = 0; i < 2000 && !lab.writer.counters().failed; ++i) {
            lab.commit(o, now, payload, now);
            now += 1000;
            // Let the writer's thread take up each 50 before the next (on a busy machine it may not
            // run for a while, and the first batch would then overflow the limit alone).
            if (i % 50 == 49) {
                (void)cpm_test::wait_until([&] {
                    const auto c = lab.writer.counters();
                    return c.failed || c.waiting == 0;
                }, std::chrono::seconds(5));
            }
        }
        for (int i = 0; i < 200 && !lab.writer.counters().failed; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
        const auto c = lab.writer.counters();
        ASSERT_TRUE(c.failed) << "256 KiB cannot hold 2000 samples of 1000 bytes";
        EXPECT_NE(c.error.find(path), std::string::npos) << c.error;
        EXPECT_NE(c.error.find("full"), std::string::npos) << c.error;
        EXPECT_GT(c.written, 50u);
        EXPECT_GT(c.dropped, 0u);
        // The live store still has everything; the file what it says it wrote.
        lab.commit(o, now, payload, now);
        EXPECT_EQ(lab.store.info(o)->samples_total, c.queued + 1);
        lab.writer.close();
        EXPECT_EQ(lab.writer.counters().waiting, 0u);
        const auto rec = load_recording(path);
        EXPECT_EQ(rec.samples, lab.writer.counters().written);
        auto first = answer(*rec.store, request("at", "big", "", 1000));
        ASSERT_EQ(first.status(), "ok");
        EXPECT_EQ(first.samples()[0].payload(), payload);
    }
}

TEST(Recording, ATruncatedFileAnswersUpToTheDamageAndSaysSo)
{
    for (const std::string format : {"db", "mcap"}) {
        SCOPED_TRACE("a recording in " + format);
        TempDir dir;
        const std::string path = dir.file("cut." + format);
        {
            Lab lab(path);
            const Oid o = lab.add({.topic = "t", .type_name = "Blob", .created_ts = 1});
            const std::vector<uint8_t> payload(200, 7);
            for (uint64_t i = 1; i <= 5000; ++i) lab.commit(o, i * 1000, payload, i * 1000);
        }
        const auto whole = load_recording(path);
        ASSERT_EQ(whole.samples, 5000u);
        fs::resize_file(path, fs::file_size(path) / 2);
        const auto cut = load_recording(path);
        EXPECT_FALSE(cut.complete);
        EXPECT_NE(cut.warning.find(path), std::string::npos) << cut.warning;
        EXPECT_NE(cut.warning.find("damaged"), std::string::npos) << cut.warning;
        EXPECT_GT(cut.samples, 1000u) << cut.warning;
        EXPECT_LT(cut.samples, 5000u);
        auto r = answer(*cut.store, request("at", "t", "", 1000 * 500));
        ASSERT_EQ(r.status(), "ok") << cut.warning;
        EXPECT_EQ(r.samples()[0].commit_ns(), 500'000u);
    }
}

TEST(Recording, ObjectsKeepTheirOidsEvenWhereTheLiveStoreReusedASlot)
{
    for (const std::string format : {"db", "mcap"}) {
        SCOPED_TRACE("a recording in " + format);
        TempDir dir;
        const std::string path = dir.file("slots." + format);
        Oid first, second, child;
        {
            Store store({.default_retention = {.window_ns = 100}});
            RecordingWriter writer(path);
            auto add = [&](ObjectInfo i) {
                const Oid oid = store.add_object(std::move(i));
                writer.object_added(*store.info(oid));
                return oid;
            };
            first = add({.kind = ObjectKind::process, .name = "a", .type_name = "participant", .created_ts = 1});
            store.mark_deleted(first, 10);
            writer.object_deleted(first, 10);
            store.expire(1000);  // purged: its slot is free for the next object
            second = add({.kind = ObjectKind::process, .name = "b", .type_name = "participant", .created_ts = 1001});
            ASSERT_EQ(uint32_t(second), uint32_t(first)) << "the store reuses the slot";
            child = add({.topic = "x", .type_name = "X", .parent = second, .created_ts = 1002});
        }
        const auto rec = load_recording(path);
        auto b = rec.store->info(second);
        ASSERT_TRUE(b) << "the newer object keeps the oid the live store knew last";
        EXPECT_EQ(b->name, "b");
        auto c = rec.store->info(child);
        ASSERT_TRUE(c);
        EXPECT_EQ(c->topic, "x");
        EXPECT_EQ(c->parent, second);
        auto objects = rec.store->search({.name_regex = "^a$"});
        ASSERT_EQ(objects.size(), 1u) << "the purged object is in the recording, under another oid";
        EXPECT_NE(objects[0].oid, second);
        EXPECT_EQ(objects[0].deleted_ts, 10u);
    }
}

TEST(Recording, ASplitRecordingReadAsOneEqualsItsStoreAndEachFileStandsAlone)
{
    for (const std::string format : {"db", "mcap"}) {
        SCOPED_TRACE("a recording in " + format);
        TempDir dir;
        const std::string path = dir.file("run." + format);
        std::vector<HistoryRequest> questions;
        std::vector<std::string> live;
        std::vector<std::string> files;
        {
            Lab lab(path, {.name = "split", .flush_period_ns = 1'000'000, .split_bytes = 160 * 1024});
            const Oid car = lab.add({.topic = "vehicleState", .key = "5", .type_name = "VehicleState", .created_ts = 1000});
            // Transient-local: each file begins with its newest value again.
            const Oid param = lab.add({.topic = "parameter", .key = "speed", .type_name = "Parameter", .created_ts = 1000});
            const Oid gone = lab.add({.topic = "log", .type_name = "Log", .created_ts = 1000});
            std::mt19937 rng(3);
            for (uint64_t i = 0; i < 3000; ++i) {
                std::vector<uint8_t> payload(100 + rng() % 100);
                for (auto& b : payload) b = uint8_t(rng());
                const uint64_t now = 2000 + i * 10;
                lab.commit(car, now - 2, payload, now);
                if (i % 500 == 0) lab.commit(param, now, payload, now + 1);
                if (i < 10) lab.commit(gone, now, payload, now + 2);
                if (i % 100 == 99) std::this_thread::sleep_for(std::chrono::milliseconds(3));  // batches reach the writer
            }
            lab.remove(gone, 2500);
            lab.writer.close();
            files = lab.writer.files();
            EXPECT_EQ(lab.writer.counters().written, 3000u + 6u + 10u) << "each sample once, the carried ones not counted";
            for (const std::string kind : {"at", "older", "younger"}) {
                for (uint64_t t : {1999ull, 2000ull, 9005ull, 17000ull, 31990ull, 40000ull}) {
                    questions.push_back(request(kind, "vehicleState", "5", t));
                    questions.push_back(request(kind, "parameter", "speed", t));
                }
            }
            questions.push_back(request("range", "vehicleState", "5", 0, 100000));
            questions.push_back(request("range", "parameter", "speed", 0, 100000));
            questions.push_back(request("range", "log", "", 0, 100000));
            questions.push_back(request("list", "", "", 0));
            for (const auto& q : questions) live.push_back(text(answer(lab.store, q)));
        }
        ASSERT_GE(files.size(), 3u) << "a split every 160 KiB";
        for (size_t i = 0; i < files.size(); ++i) {
            char name[32];
            std::snprintf(name, sizeof name, "run_%03zu.", i);
            EXPECT_EQ(fs::path(files[i]).filename(), name + format);
            // Alone: the IDL, the objects, the parameter's value at the file's start.
            const auto one = load_recording(files[i]);
            EXPECT_TRUE(one.complete) << one.warning;
            ASSERT_TRUE(one.types);
            const auto p = one.store->find("parameter", "speed");
            ASSERT_TRUE(p) << files[i];
            EXPECT_TRUE(one.store->latest(*p).ok()) << files[i] << ": the newest parameter value is carried";
        }
        // As one, through the folder: every sample once, every answer as the store gave it.
        const auto whole = load_recording(dir.path.string());
        EXPECT_TRUE(whole.complete) << whole.warning;
        EXPECT_EQ(whole.samples, 3016u);
        for (size_t i = 0; i < questions.size(); ++i) {
            EXPECT_EQ(text(answer(*whole.store, questions[i])), live[i]) << "question " << i << ": " << questions[i].kind() << " " << questions[i].topic()
                                                                         << " t0=" << questions[i].t0();
        }
    }
}

TEST(Recording, ASplitRecordingKeepsItsNewestFilesUnderItsLimit)
{
    TempDir dir;
    const std::string path = dir.file("capped.db");
    Lab lab(path, {.flush_period_ns = 1'000'000, .split_bytes = 128 * 1024, .max_total_bytes = 600 * 1024});
    const Oid car = lab.add({.topic = "vehicleState", .key = "5", .type_name = "VehicleState", .created_ts = 1000});
    const std::vector<uint8_t> payload(200, 9);
    for (uint64_t i = 0; i < 8000; ++i) {
        lab.commit(car, 1000 + i, payload, 2000 + i * 10);
        if (i % 100 == 99) std::this_thread::sleep_for(std::chrono::milliseconds(3));
    }
    lab.writer.close();
    const auto files = lab.writer.files();
    uint64_t total = 0;
    for (const auto& f : files) total += fs::file_size(f);
    EXPECT_LE(total, 600u * 1024 + 200u * 1024) << "at most the limit, and the file being written when it was checked";
    EXPECT_FALSE(fs::exists(dir.file("capped_000.db"))) << "the oldest went";
    EXPECT_TRUE(fs::exists(files.back()));
    const auto rest = load_recording(dir.path.string());
    const auto newest = answer(*rest.store, request("latest", "vehicleState", "5", 0));
    ASSERT_EQ(newest.status(), "ok");
    EXPECT_EQ(newest.samples()[0].commit_ns(), 2000u + 7999u * 10) << "the newest files are kept";
    EXPECT_LT(rest.samples, 8000u);
}

TEST(Recording, AFolderReadsItsRunsRecordingBeforeAnySaveAndItsPartsInNumberOrder)
{
    TempDir dir;
    auto one = [&](const std::string& file, uint64_t t) {
        Lab lab(file);
        const Oid o = lab.add({.topic = "t", .type_name = "Blob", .created_ts = 1});
        lab.commit(o, t, {1, 2, 3}, t);
    };
    one(dir.file("recording.db"), 1000);
    one(dir.file("save_20261204T101010.000Z_fsmStatus_123.db"), 2000);  // a save in the run's folder
    const auto run = load_recording(dir.path.string());
    EXPECT_EQ(answer(*run.store, request("latest", "t", "", 0)).samples().at(0).commit_ns(), 1000u);
    // Parts numbered past 999 come after 999.
    TempDir parts;
    fs::copy_file(dir.file("recording.db"), parts.file("run_999.db"));
    fs::copy_file(dir.file("save_20261204T101010.000Z_fsmStatus_123.db"), parts.file("run_1000.db"));
    // Both are single recordings of their own (each a start of its own): refused as one set.
    try {
        (void)load_recording(parts.path.string());
        FAIL() << "two recordings read as one";
    } catch (const cpm::Error& e) {
        EXPECT_NE(std::string(e.what()).find("run_1000.db is of another recording than"), std::string::npos) << e.what();
    }
}
