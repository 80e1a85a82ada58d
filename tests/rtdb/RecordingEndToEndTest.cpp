// cpm_history --record as a real process: the recording of a run answers `cpm history --file`
// byte for byte as the live service answered the same questions, and each answers with the
// status and content the writers' samples call for; a recording survives Ctrl-C
// and kill -9; a full disk ends the recording with an error naming the file while the live
// history goes on serving; cpm record writes the same file.
#include <cpm/HistoryClient.hpp>
#include <cpm/Participant.hpp>
#include <cpm/rtdb/Mcap.hpp>
#include <cpm/rtdb/Recording.hpp>

#include <cpm_test/Dds.hpp>
#include <cpm_test/Isolation.hpp>
#include <cpm_test/McapCheck.hpp>
#include <cpm_test/Process.hpp>

#include <VehicleState.h>

#include "history_e2e.hpp"

#include <cpm_test/TempDir.hpp>
#include <cpm_test/SourceDir.hpp>

#include <gtest/gtest.h>
#include <sqlite3.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <functional>
#include <set>
#include <tuple>
#include <sstream>
#include <unistd.h>

using namespace std::chrono_literals;
using cpm_test::built_program;
using cpm_test::Process;
namespace fs = std::filesystem;

using cpm_test::TempDir;

namespace {




Process writer(std::vector<std::string> args)
{
    args.insert(args.begin(), built_program("history_writer"));
    return Process(args);
}

struct Answer
{
    int code;
    std::string out, err;
};

/// `cpm history ARGS` (with --file FILE when given).
Answer ask(std::vector<std::string> args, const std::string& file = "")
{
    args.insert(args.begin(), {built_program("cpm"), "history"});
    if (!file.empty()) args.insert(args.end(), {"--file", file});
    Process p(args);
    const int code = p.wait(30s);
    return {code, p.output(), p.errors()};
}

/// Every row of a recording's table in its order, as text (blobs in hex), read with SQLite itself.
std::vector<std::string> recorded_rows(const std::string& file, const std::string& table)
{
    sqlite3* db = nullptr;
    std::vector<std::string> rows;
    if (sqlite3_open_v2(file.c_str(), &db, SQLITE_OPEN_READONLY, nullptr) != SQLITE_OK) {
        sqlite3_close(db);
        return {"cannot open " + file};
    }
    sqlite3_stmt* q = nullptr;
    if (sqlite3_prepare_v2(db, ("SELECT * FROM " + table + " ORDER BY rowid").c_str(), -1, &q, nullptr) == SQLITE_OK) {
        while (sqlite3_step(q) == SQLITE_ROW) {
            std::string row;
            for (int c = 0; c < sqlite3_column_count(q); ++c) {
                if (sqlite3_column_type(q, c) == SQLITE_BLOB) {
                    const auto* b = static_cast<const uint8_t*>(sqlite3_column_blob(q, c));
                    char hex[3];
                    for (int i = 0; i < sqlite3_column_bytes(q, c); ++i) {
                        std::snprintf(hex, sizeof hex, "%02x", b[i]);
                        row += hex;
                    }
                } else {
                    const auto* t = sqlite3_column_text(q, c);
                    row += t ? reinterpret_cast<const char*>(t) : "NULL";
                }
                row += "|";
            }
            rows.push_back(row);
        }
    } else {
        rows.push_back(std::string("cannot read ") + table + " of " + file + ": " + sqlite3_errmsg(db));
    }
    sqlite3_finalize(q);
    sqlite3_close(db);
    return rows;
}

/// Objects as JSON lines without the two fields that depend on when they are asked.
std::string without_now(const std::string& lines)
{
    std::istringstream in(lines);
    std::string out;
    for (std::string line; std::getline(in, line);) {
        auto j = nlohmann::json::parse(line);
        j.erase("rate_hz");
        j.erase("newest_age_s");
        out += j.dump() + "\n";
    }
    return out;
}

}  // namespace

TEST(RecordingEndToEnd, ARecordedRunAnswersEveryVerbAsTheLiveServiceDid)
{
    TempDir dir;
    const std::string file = dir.file("recording.db");
    cpm::Participant participant{udp_only()};
    cpm::HistoryClient client{participant};
    Process service({built_program("cpm_history"), "--window", "60s", "--record", file, "--record-name", "e2e"});
    Process cars = writer({"--type", "vehicle", "--vehicle", "3", "--count", "80"});
    Process things = writer({"--type", "lab_only", "--topic", "labThing", "--vehicle", "2", "--count", "40"});  // a type cpm lacks
    Process gone = writer({"--type", "vehicle", "--vehicle", "4", "--count", "20", "--dispose"});
    ASSERT_EQ(cars.wait(30s), 0) << cars.errors();
    ASSERT_EQ(things.wait(30s), 0) << things.errors();
    ASSERT_EQ(gone.wait(30s), 0) << gone.errors();
    ASSERT_TRUE(wait_for_samples(client, "vehicleState", "3", 80)) << service.errors();
    ASSERT_TRUE(wait_for_samples(client, "labThing", "2", 40)) << service.errors();
    ASSERT_TRUE(cpm_test::wait_until([&] {
        auto r = client.latest("vehicleState", "4");
        return !r.objects().empty() && r.objects()[0].deleted_ts() != 0;
    }, 30s, 20ms)) << "the disposed instance is marked deleted";

    // Commit times as the service gave them, to ask by commit time too.
    const auto commits_of = [&](const char* topic, const char* key) {
        const Answer all = ask({"range", "--topic", topic, "--key", key, "--from", "0", "--to", std::to_string(UINT64_MAX / 2), "--json"});
        EXPECT_EQ(all.code, 0) << all.err;
        std::vector<uint64_t> commits;
        std::istringstream lines(all.out);
        for (std::string line; std::getline(lines, line);) commits.push_back(nlohmann::json::parse(line)["commit_ns"].get<uint64_t>());
        return commits;
    };
    const std::vector<uint64_t> commits = commits_of("vehicleState", "3"), thing_commits = commits_of("labThing", "2");
    ASSERT_EQ(commits.size(), 80u);
    ASSERT_EQ(thing_commits.size(), 40u);
    const auto t = [](uint64_t v) { return std::to_string(v); };
    // Each question with what the writers' samples say it must answer: its exit code and one
    // content check (the history_writer's k-th sample has data time kBase + k ms and, for
    // vehicleState, pose.x = k; commit order is write order within an object).
    const auto data_of = [](const nlohmann::json& j) { return (j["data_ns"].get<uint64_t>() - kBase) / kMs; };  // k
    const auto first = [](const Answer& a) { return nlohmann::json::parse(a.out.substr(0, a.out.find('\n'))); };
    const auto lines_of = [](const Answer& a) {
        std::vector<nlohmann::json> out;
        std::istringstream in(a.out);
        for (std::string line; std::getline(in, line);) out.push_back(nlohmann::json::parse(line));
        return out;
    };
    const auto sample_k = [&](uint64_t k) {  // a JSON answer holding vehicleState/3's sample k
        return [&, k](const Answer& a) {
            const auto j = first(a);
            EXPECT_EQ(j["status"], "ok") << a.out;
            EXPECT_EQ(data_of(j), k) << a.out;
            if (j.contains("data")) {
                EXPECT_EQ(j["data"]["pose"]["x"], double(k)) << a.out;
            }
        };
    };
    const auto status_is = [&](const char* status) { return [&, status](const Answer& a) { EXPECT_EQ(first(a)["status"], status) << a.out; }; };
    const auto text_holds = [](const std::string& what) {
        return [what](const Answer& a) { EXPECT_NE(a.out.find(what), std::string::npos) << "no '" << what << "' in\n" << a.out; };
    };
    const std::string data_time = "data time                        2023-11-14T22:13:20.0";  // kBase + k ms, k as two digits
    struct Question
    {
        std::vector<std::string> args;
        int code;
        std::function<void(const Answer&)> check;
    };
    const std::vector<Question> questions = {
        {{"latest", "--topic", "vehicleState", "--key", "3", "--json"}, 0, sample_k(79)},
        {{"latest", "--topic", "labThing", "--key", "2", "--json"}, 0, [&](const Answer& a) { EXPECT_EQ(data_of(first(a)), 39u) << a.out; }},
        {{"latest", "--topic", "vehicleState", "--key", "4", "--json"}, 0, [&](const Answer& a) {  // disposed: its last sample stays
             EXPECT_EQ(data_of(first(a)), 19u) << a.out;
             EXPECT_EQ(first(a)["data"]["vehicle_id"], 4) << a.out;
         }},
        {{"at", "--topic", "vehicleState", "--key", "3", "--time", t(commits[40]), "--json"}, 0, sample_k(40)},
        {{"at", "--topic", "vehicleState", "--key", "3", "--time", t(commits[40] - 1)}, 0, text_holds(data_time + "39000000Z")},
        {{"older", "--topic", "vehicleState", "--key", "3", "--time", t(commits[10]), "--json"}, 0, sample_k(9)},
        {{"younger", "--topic", "vehicleState", "--key", "3", "--time", t(commits[79]), "--json"}, 1, status_is("not_yet")},
        {{"at", "--topic", "vehicleState", "--key", "3", "--time", t(kBase + 33 * kMs + 1), "--by", "data", "--json"}, 0, sample_k(33)},
        {{"at", "--topic", "vehicleState", "--key", "3", "--time", t(kBase - 1), "--by", "data", "--json"}, 1, status_is("not_found")},
        {{"older", "--topic", "labThing", "--key", "2", "--time", t(kBase + 20 * kMs), "--by", "data", "--json"}, 0,
         [&](const Answer& a) { EXPECT_EQ(data_of(first(a)), 19u) << a.out; }},
        {{"younger", "--topic", "labThing", "--key", "2", "--time", t(kBase + 20 * kMs), "--by", "data"}, 0, text_holds(data_time + "21000000Z")},
        {{"range", "--topic", "vehicleState", "--key", "3", "--from", t(kBase + 5 * kMs), "--to", t(kBase + 25 * kMs), "--by", "data", "--json"}, 0,
         [&](const Answer& a) {  // [from, to): samples 5 to 24
             const auto lines = lines_of(a);
             ASSERT_EQ(lines.size(), 20u) << a.out;
             for (size_t i = 0; i < lines.size(); ++i) EXPECT_EQ(lines[i]["data"]["pose"]["x"], double(5 + i)) << lines[i].dump();
         }},
        {{"range", "--topic", "labThing", "--key", "2", "--from", t(thing_commits[5]), "--to", t(thing_commits[30]), "--limit", "7", "--json"}, 0,
         [&](const Answer& a) {  // samples 5 to 11 committed in the window (25 of them), the seven asked for, then where the rest starts
             const auto lines = lines_of(a);
             ASSERT_EQ(lines.size(), 8u) << a.out;
             for (size_t i = 0; i < 7; ++i) EXPECT_EQ(data_of(lines[i]), 5 + i) << a.out;
             EXPECT_EQ(lines[7]["status"], "truncated") << a.out;
         }},
        {{"successor", "--topic", "vehicleState", "--key", "3", "--time", t(commits[50]), "--json"}, 0, sample_k(51)},
        {{"snapshot", "--objects", "vehicleState/3,labThing/2,vehicleState/4", "--time", t(commits[60]), "--json"}, 0,
         [&](const Answer& a) {  // each object as it was then: vehicleState/3's sample 60, the others committed no later
             const auto lines = lines_of(a);
             ASSERT_EQ(lines.size(), 3u) << a.out;
             std::set<std::string> objects;
             for (const auto& j : lines) {
                 objects.insert(j["topic"].get<std::string>() + "/" + j["key"].get<std::string>());
                 EXPECT_EQ(j["status"], "ok") << j.dump();
                 EXPECT_LE(j["commit_ns"].get<uint64_t>(), commits[60]) << j.dump();
                 if (j["topic"] == "vehicleState" && j["key"] == "3") {
                     EXPECT_EQ(data_of(j), 60u) << j.dump();
                 }
             }
             EXPECT_EQ(objects, (std::set<std::string>{"vehicleState/3", "labThing/2", "vehicleState/4"}));
         }},
        {{"snapshot", "--objects", "vehicleState/3,labThing/2", "--time", t(commits[60])}, 0, text_holds(data_time + "60000000Z")},
    };
    std::vector<Answer> live;
    for (const auto& q : questions) live.push_back(ask(q.args));
    // Live, each answers what the writers wrote.
    for (size_t i = 0; i < questions.size(); ++i) {
        std::string q;
        for (const auto& a : questions[i].args) q += a + " ";
        SCOPED_TRACE("live: cpm history " + q);
        EXPECT_EQ(live[i].code, questions[i].code) << live[i].err;
        if (live[i].code == questions[i].code) questions[i].check(live[i]);
    }
    const Answer live_search = ask({"search", "--name", "vehicleState|labThing", "--json"});
    ASSERT_EQ(live_search.code, 0) << live_search.err;

    service.kill(SIGINT);  // Ctrl-C: the recording is closed
    ASSERT_EQ(service.wait(30s), 0) << service.errors();
    const auto counts = nlohmann::json::parse(service.output());
    EXPECT_GE(counts["recording"]["written"].get<uint64_t>(), 140u) << service.output();
    EXPECT_EQ(counts["recording"]["dropped"], 0) << service.output();
    EXPECT_TRUE(fs::exists(file));
    EXPECT_FALSE(fs::exists(file + "-wal")) << "a closed recording is one file";

    for (size_t i = 0; i < questions.size(); ++i) {
        const Answer recorded = ask(questions[i].args, file);
        std::string q;
        for (const auto& a : questions[i].args) q += a + " ";
        EXPECT_EQ(recorded.code, live[i].code) << q << recorded.err;
        EXPECT_EQ(recorded.out, live[i].out) << q;
        EXPECT_FALSE(recorded.out.empty() && recorded.code == 0) << q;
    }
    // The answer cut at --limit 7 ends with a line that says so and where the rest starts.
    {
        const Answer seven = ask({"range", "--topic", "labThing", "--key", "2", "--from", "0", "--to", t(UINT64_MAX / 2), "--limit", "7", "--json"}, file);
        EXPECT_EQ(seven.code, 0) << seven.err;
        std::vector<nlohmann::json> cut;
        std::istringstream in(seven.out);
        for (std::string line; std::getline(in, line);) cut.push_back(nlohmann::json::parse(line));
        ASSERT_EQ(cut.size(), 8u) << seven.out;
        EXPECT_EQ(cut[6]["topic"], "labThing");
        EXPECT_EQ(cut[7]["status"], "truncated") << cut[7].dump();
        EXPECT_EQ(cut[7]["next_from_ns"], cut[6]["commit_ns"].get<uint64_t>() + 1) << cut[7].dump();
    }
    const Answer recorded_search = ask({"search", "--name", "vehicleState|labThing", "--json"}, file);
    ASSERT_EQ(recorded_search.code, 0) << recorded_search.err;
    EXPECT_EQ(without_now(recorded_search.out), without_now(live_search.out));

    // CSV out, in and out again: every field of every sample (both keys) as it was.
    const Answer csv = ask({"export", "--topic", "vehicleState", "--csv"}, file);
    ASSERT_EQ(csv.code, 0) << csv.err;
    EXPECT_EQ(std::count(csv.out.begin(), csv.out.end(), '\n'), 1 + 80 + 20) << "a header and every sample";
    EXPECT_EQ(csv.out.rfind("commit_ns,data_ns,valid_after_ns,key,header.create_stamp.nanoseconds,", 0), 0u) << csv.out.substr(0, 200);
    std::ofstream(dir.file("vehicleState.csv")) << csv.out;
    Process import({built_program("cpm"), "record", "import", dir.file("vehicleState.csv"), "--topic", "vehicleState", "--type",
                    "VehicleState", "--out", dir.file("imported.db")});
    ASSERT_EQ(import.wait(30s), 0) << import.errors();
    const Answer round_trip = ask({"export", "--topic", "vehicleState", "--csv"}, dir.file("imported.db"));
    ASSERT_EQ(round_trip.code, 0) << round_trip.err;
    EXPECT_EQ(round_trip.out, csv.out);
    const Answer undecodable = ask({"export", "--topic", "labThing", "--csv"}, file);
    EXPECT_EQ(undecodable.code, 1);
    EXPECT_NE(undecodable.err.find("LabOnlyThing"), std::string::npos) << undecodable.err;

    // The recording keeps its run's creators and the types it knew; a program opens it too.
    auto recording = cpm::HistoryClient::open_recording(file);
    auto r = recording.at<VehicleState>("vehicleState", 3, kBase + 70 * kMs, cpm::HistoryBy::data);
    ASSERT_TRUE(r.ok()) << r.status;
    EXPECT_EQ(r.sample.pose().x(), 70);
    // Relative times count back from the run's end.
    const Answer relative = ask({"at", "--topic", "vehicleState", "--key", "3", "--time", "now", "--json"}, file);
    EXPECT_EQ(relative.code, 0) << relative.err;
    EXPECT_EQ(nlohmann::json::parse(relative.out)["commit_ns"], commits[79]);

    // The same recording as MCAP: the format's reference reader reads every message as cpm
    // decodes it, every question answers as from the SQLite file, and it comes back to SQLite
    // byte for byte.
    const std::string mcap = dir.file("recording.mcap");
    Process to_mcap({built_program("cpm"), "history", "--file", file, "export", "--mcap", mcap});
    ASSERT_EQ(to_mcap.wait(60s), 0) << to_mcap.errors();
    EXPECT_EQ(cpm_test::mcap_differences(mcap, long(counts["recording"]["written"].get<uint64_t>())), "");
    for (const auto& q : questions) {
        std::string text;
        for (const auto& a : q.args) text += a + " ";
        const Answer from_db = ask(q.args, file), from_mcap = ask(q.args, mcap);
        EXPECT_EQ(from_mcap.code, from_db.code) << text << from_mcap.err;
        EXPECT_EQ(from_mcap.out, from_db.out) << text;
    }
    EXPECT_EQ(without_now(ask({"search", "--name", "vehicleState|labThing", "--json"}, mcap).out), without_now(recorded_search.out));
    const std::string back = dir.file("back.db");
    Process to_sqlite({built_program("cpm"), "history", "--file", mcap, "export", "--sqlite", back});
    ASSERT_EQ(to_sqlite.wait(60s), 0) << to_sqlite.errors();
    EXPECT_EQ(recorded_rows(back, "samples"), recorded_rows(file, "samples")) << "every sample, every time, every payload byte";
    EXPECT_EQ(recorded_rows(back, "objects"), recorded_rows(file, "objects"));
    EXPECT_EQ(recorded_rows(back, "types"), recorded_rows(file, "types"));
}

TEST(RecordingEndToEnd, ARecordingKilledMidRunStillAnswersUpToItsLastBatch)
{
  for (const std::string format : {"db", "mcap"}) {
    SCOPED_TRACE("recording to " + format);
    TempDir dir;
    const std::string file = dir.file("killed." + format);
    cpm::Participant participant{udp_only()};
    cpm::HistoryClient client{participant};
    Process service({built_program("cpm_history"), "--record", file});
    Process cars = writer({"--type", "vehicle", "--vehicle", "3", "--count", "60"});
    ASSERT_EQ(cars.wait(30s), 0) << cars.errors();
    ASSERT_TRUE(wait_for_samples(client, "vehicleState", "3", 60)) << service.errors();
    // Past the writer thread's batch period (100 ms) and an MCAP chunk's (a second): on disk.
    std::this_thread::sleep_for(format == "db" ? 500ms : 1500ms);
    service.kill(SIGKILL);
    service.wait(10s);
    const Answer latest = ask({"latest", "--topic", "vehicleState", "--key", "3", "--json"}, file);
    ASSERT_EQ(latest.code, 0) << latest.err;
    EXPECT_EQ(nlohmann::json::parse(latest.out)["data"]["pose"]["x"], 59);
    EXPECT_NE(latest.err.find("was not closed"), std::string::npos) << latest.err;
    EXPECT_NE(latest.err.find(file), std::string::npos) << latest.err;
  }
}

TEST(RecordingEndToEnd, AFullDiskEndsTheRecordingWithAnErrorAndTheLiveHistoryGoesOn)
{
  for (const std::string format : {"db", "mcap"}) {
    SCOPED_TRACE("recording to " + format);
    TempDir dir;
    const std::string file = dir.file("small." + format);
    cpm::Participant participant{udp_only()};
    cpm::HistoryClient client{participant};
    Process service({built_program("cpm_history"), "--record", file, "--record-max-bytes", "65536"});
    Process cars = writer({"--type", "vehicle", "--vehicle", "3", "--count", "1500"});
    ASSERT_EQ(cars.wait(60s), 0) << cars.errors();
    ASSERT_TRUE(wait_for_samples(client, "vehicleState", "3", 1500)) << service.errors();
    ASSERT_TRUE(cpm_test::wait_until([&] { return service.errors().find("the recording stopped") != std::string::npos; }, 20s, 20ms))
        << service.errors();
    EXPECT_NE(service.errors().find(file), std::string::npos) << service.errors();
    EXPECT_NE(service.errors().find("full"), std::string::npos) << service.errors();
    // Still serving, with everything.
    auto newest = client.latest<VehicleState>("vehicleState", 3);
    ASSERT_TRUE(newest.ok()) << newest.status;
    EXPECT_EQ(newest.sample.pose().x(), 1499);
    service.kill(SIGINT);
    EXPECT_EQ(service.wait(30s), 1) << "a failed recording is a failed run\n" << service.output() << service.errors();
    // What was written reads.
    const Answer first = ask({"at", "--topic", "vehicleState", "--key", "3", "--by", "data", "--time", std::to_string(kBase), "--json"}, file);
    ASSERT_EQ(first.code, 0) << first.err;
    EXPECT_EQ(nlohmann::json::parse(first.out)["data"]["pose"]["x"], 0);
    EXPECT_EQ(first.err, "") << "closed whole, up to where the limit stopped it";
    if (format == "mcap") {
        EXPECT_LE(fs::file_size(file), 65536u);
        EXPECT_EQ(cpm_test::mcap_differences(file), "") << "a valid file, summary and all";
    }
  }
}

TEST(RecordingEndToEnd, CpmRecordWritesTheSameFileAndRefusesToOverwriteOne)
{
    TempDir dir;
    const std::string file = dir.file("cpm_record.db");
    Process record({built_program("cpm"), "record", file, "--topics", "vehicle*", "--duration", "20s"});
    Process cars = writer({"--type", "vehicle", "--vehicle", "7", "--count", "30"});
    ASSERT_EQ(cars.wait(30s), 0) << cars.errors();
    record.kill(SIGINT);
    ASSERT_EQ(record.wait(30s), 0) << record.errors();
    const auto counts = nlohmann::json::parse(record.output());
    EXPECT_EQ(counts["written"], 30) << record.output();
    const Answer range = ask({"range", "--topic", "vehicleState", "--key", "7", "--by", "data", "--from", std::to_string(kBase), "--to",
                              std::to_string(kBase + 30 * kMs), "--json"}, file);
    ASSERT_EQ(range.code, 0) << range.err;
    EXPECT_EQ(std::count(range.out.begin(), range.out.end(), '\n'), 30);
    // --topics vehicle* leaves the rest out (cpm's own log, parameter and status topics).
    const Answer list = ask({"list", "--json"}, file);
    ASSERT_EQ(list.code, 0) << list.err;
    std::istringstream objects(list.out);
    int instances = 0;
    for (std::string line; std::getline(objects, line);) {
        const auto o = nlohmann::json::parse(line);
        if (o["kind"] != "instance") continue;
        ++instances;
        EXPECT_EQ(o["topic"].get<std::string>().rfind("vehicle", 0), 0u) << line;
    }
    EXPECT_EQ(instances, 1) << list.out;

    Process again({built_program("cpm"), "record", file});
    EXPECT_EQ(again.wait(20s), 2);
    EXPECT_NE(again.errors().find(file + ": the file exists already"), std::string::npos) << again.errors();
    Process not_one({built_program("cpm"), "history", "list", "--file", dir.file("none.db")});
    EXPECT_EQ(not_one.wait(20s), 1);
    EXPECT_NE(not_one.errors().find(dir.file("none.db") + ": no such file"), std::string::npos) << not_one.errors();
}

namespace {

/// Every sample of a topic in a recording, all keys, in commit order: key and payload.
std::vector<std::pair<std::string, std::vector<uint8_t>>> topic_samples(const cpm::rtdb::LoadedRecording& rec, const std::string& topic)
{
    std::vector<std::tuple<uint64_t, std::string, std::vector<uint8_t>>> all;
    for (const auto& o : rec.store->search({.name_regex = "^" + topic + "(/|$)", .kind = cpm::rtdb::ObjectKind::instance})) {
        for (auto& s : rec.store->range(o.oid, 0, UINT64_MAX, cpm::rtdb::By::commit, 1'000'000).samples) all.emplace_back(s.commit_ns, o.key, s.payload);
    }
    std::sort(all.begin(), all.end());
    std::vector<std::pair<std::string, std::vector<uint8_t>>> out;
    for (auto& [c, key, payload] : all) out.emplace_back(key, std::move(payload));
    return out;
}

}  // namespace

TEST(RecordingEndToEnd, AReplayedRunRecordedAgainHoldsTheSameSamplesInTheSameOrder)
{
    TempDir dir;
    const std::string first = dir.file("first.db"), second = dir.file("second.db");
    cpm::Participant participant{udp_only()};
    cpm::HistoryClient client{participant};
    {
        Process service({built_program("cpm_history"), "--record", first});
        Process cars = writer({"--type", "vehicle", "--vehicle", "3", "--count", "60"});
        Process more = writer({"--type", "vehicle", "--vehicle", "5", "--count", "40"});
        Process things = writer({"--type", "lab_only", "--topic", "labThing", "--vehicle", "2", "--count", "30"});
        ASSERT_EQ(cars.wait(30s), 0) << cars.errors();
        ASSERT_EQ(more.wait(30s), 0) << more.errors();
        ASSERT_EQ(things.wait(30s), 0) << things.errors();
        ASSERT_TRUE(wait_for_samples(client, "labThing", "2", 30)) << service.errors();
        ASSERT_TRUE(wait_for_samples(client, "vehicleState", "5", 40)) << service.errors();
        service.kill(SIGINT);
        ASSERT_EQ(service.wait(30s), 0) << service.errors();
    }
    Process again({built_program("cpm_history"), "--record", second});
    // The new service must know the topics before the replay starts: cpm play waits for a
    // reader of each, and the service subscribes once it discovers the player's writers.
    Process play({built_program("cpm"), "play", first, "--topics", "vehicleState,labThing", "--rate", "4", "--wait-for-readers", "20s"});
    ASSERT_EQ(play.wait(60s), 0) << play.errors();
    const auto stats = nlohmann::json::parse(play.output());
    EXPECT_EQ(stats["published"], 130) << play.output();
    EXPECT_EQ(play.errors().find("no reader"), std::string::npos) << play.errors();
    ASSERT_TRUE(cpm_test::wait_until([&] {
        auto r = client.latest("labThing", "2");
        return !r.objects().empty() && r.objects()[0].samples_total() >= 30;
    }, 20s, 20ms)) << again.errors();
    again.kill(SIGINT);
    ASSERT_EQ(again.wait(30s), 0) << again.errors();

    const auto a = cpm::rtdb::load_recording(first), b = cpm::rtdb::load_recording(second);
    for (const std::string topic : {"vehicleState", "labThing"}) {
        const auto before = topic_samples(a, topic), after = topic_samples(b, topic);
        ASSERT_EQ(after.size(), before.size()) << topic;
        for (size_t i = 0; i < before.size(); ++i) {
            EXPECT_EQ(after[i].first, before[i].first) << topic << " sample " << i;
            EXPECT_EQ(after[i].second, before[i].second) << topic << " sample " << i;
        }
    }
}

TEST(RecordingEndToEnd, PlayNamesWhatIsWrong)
{
    TempDir dir;
    std::ofstream(dir.file("junk.db")) << "not a recording";
    Process junk({built_program("cpm"), "play", dir.file("junk.db")});
    EXPECT_EQ(junk.wait(20s), 1);
    EXPECT_NE(junk.errors().find(dir.file("junk.db")), std::string::npos) << junk.errors();
    Process rate({built_program("cpm"), "play", dir.file("junk.db"), "--rate", "0"});
    EXPECT_EQ(rate.wait(20s), 2);
    EXPECT_NE(rate.errors().find("--rate"), std::string::npos) << rate.errors();
    Process none({built_program("cpm"), "play"});
    EXPECT_EQ(none.wait(20s), 2);
    EXPECT_NE(none.errors().find("FILE"), std::string::npos) << none.errors();
}

/// `cpm vehicle sim` as car 3 on the corridor: a live writer stamping with the wall clock, as a car does.
Process live_car()
{
    return Process({built_program("cpm"), "vehicle", "sim", "--id", "3", "--map", cpm_test::source_dir() + "/scenarios/maps/corridor.json",
                    "--start", "0,0,0", "--realtime"});  // a car keeps its 50 Hz as a real one would
}

TEST(DashCam, ASaveHoldsExactlyTheSpanAskedAndTheLiveHistoryLosesNothing)
{
    TempDir dir;
    cpm::Participant participant{udp_only()};
    cpm::HistoryClient client{participant};
    Process service({built_program("cpm_history"), "--save-dir", dir.path.string()});
    Process car = live_car();
    ASSERT_TRUE(wait_for_samples(client, "vehicleState", "3", 100)) << service.errors() << car.errors();
    // One second back, one ahead (the reply comes once that second has passed).
    const Answer saved = ask({"save", "dash.db", "--before", "1s", "--after", "1s", "--topics", "vehicleState,rangeSensors", "--json"});
    ASSERT_EQ(saved.code, 0) << saved.err << saved.out;
    const auto s = nlohmann::json::parse(saved.out);
    EXPECT_EQ(s["file"], dir.file("dash.db"));
    const std::string from = std::to_string(s["from_ns"].get<uint64_t>()), to = std::to_string(s["to_ns"].get<uint64_t>());
    uint64_t saved_total = 0;
    EXPECT_EQ(s["to_ns"].get<uint64_t>() - s["from_ns"].get<uint64_t>(), 2'000'000'000u);
    for (const char* topic : {"vehicleState", "rangeSensors"}) {
        SCOPED_TRACE(topic);
        const std::vector<std::string> span{"range", "--topic", topic, "--key", "3", "--from", from, "--to", to, "--by", "data", "--json"};
        const Answer in_file = ask(span, dir.file("dash.db"));
        const Answer live = ask(span);  // the service still holds the span: the same samples, none more, none fewer
        ASSERT_EQ(in_file.code, 0) << in_file.err;
        ASSERT_EQ(live.code, 0) << live.err;
        EXPECT_EQ(in_file.out, live.out);
        const auto n = std::count(in_file.out.begin(), in_file.out.end(), '\n');
        saved_total += uint64_t(n);
        EXPECT_GE(n, 80) << "two seconds at 50 Hz";
        EXPECT_LE(n, 102);
        // Nothing outside the span.
        const Answer before = ask({"older", "--topic", topic, "--key", "3", "--time", from, "--by", "data"}, dir.file("dash.db"));
        EXPECT_EQ(before.code, 1) << before.out;
        const Answer all = ask({"range", "--topic", topic, "--key", "3", "--from", "0", "--to", "9000000000000000000", "--json"}, dir.file("dash.db"));
        EXPECT_EQ(all.out, in_file.out);
    }
    EXPECT_EQ(s["samples"].get<uint64_t>(), saved_total) << "the reply counts what the file holds";
    const Answer others = ask({"latest", "--topic", "vehicleObservation", "--key", "3"}, dir.file("dash.db"));
    EXPECT_EQ(others.code, 1) << "only the topics asked for\n" << others.out;
    // The service went on meanwhile, and goes on.
    const Answer again = ask({"save", "dash.db"});
    EXPECT_EQ(again.code, 1);
    EXPECT_NE(again.err.find("exists already"), std::string::npos) << again.err;
    const Answer path = ask({"save", "../dash2.db"});
    EXPECT_EQ(path.code, 2);
    EXPECT_NE(path.err.find("a file name"), std::string::npos) << path.err;
    const Answer recording = ask({"save", "x.db"}, dir.file("dash.db"));
    EXPECT_EQ(recording.code, 2) << "a recording is copied with export";
    EXPECT_TRUE(wait_for_samples(client, "vehicleState", "3", 400)) << "still ingesting";
}

TEST(DashCam, ATriggerSavesTheSpanAroundItByItselfAsMcap)
{
    TempDir dir;
    cpm::Participant participant{udp_only()};
    cpm::HistoryClient client{participant};
    // Car 3's first state fires it (the filter matches from then on: once).
    Process service({built_program("cpm_history"), "--save-dir", dir.path.string(), "--save-on", "vehicleState=vehicle_id==3", "--save-before", "1s",
                     "--save-after", "1s", "--save-format", "mcap"});
    Process car = live_car();
    ASSERT_TRUE(cpm_test::wait_until([&] { return service.errors().find("cpm_history: saved ") != std::string::npos; }, 30s)) << service.errors();
    std::vector<std::string> files;
    for (const auto& e : fs::directory_iterator(dir.path.string())) files.push_back(e.path().filename().string());
    ASSERT_EQ(files.size(), 1u) << "one save: the state stays matched";
    EXPECT_EQ(files[0].rfind("save_", 0), 0u) << files[0];
    EXPECT_NE(files[0].find("Z_vehicleState_3.mcap"), std::string::npos) << files[0];
    EXPECT_EQ(cpm_test::mcap_differences(dir.file(files[0])), "");
    const Answer states = ask({"range", "--topic", "vehicleState", "--key", "3", "--from", "0", "--to", "9000000000000000000", "--json"}, dir.file(files[0]));
    ASSERT_EQ(states.code, 0) << states.err;
    const auto n = std::count(states.out.begin(), states.out.end(), '\n');
    EXPECT_GE(n, 40) << "the second after the first state, at 50 Hz";
    EXPECT_LE(n, 102);
    std::this_thread::sleep_for(2s);
    size_t later = 0;
    for (const auto& e : fs::directory_iterator(dir.path.string())) later += e.path().extension() == ".mcap";
    EXPECT_EQ(later, 1u) << "no save again while the filter stays matched";
}

TEST(Bookmarks, AMarkIsRecordedListedLiveAndFromTheFileAndIsTheMcapFilesMetadata)
{
    TempDir dir;
    const std::string file = dir.file("marked.mcap");
    cpm::Participant participant{udp_only()};
    cpm::HistoryClient client{participant};
    Process service({built_program("cpm_history"), "--record", file});
    ASSERT_TRUE(cpm_test::wait_until([&] { return !client.latest("historyStatus", "").objects().empty(); }, 30s)) << service.errors();
    Process first({built_program("cpm"), "lab", "mark", "car 3 touched the wall"});
    ASSERT_EQ(first.wait(30s), 0) << first.errors();
    EXPECT_NE(first.output().find("marked "), std::string::npos) << first.output();
    Process second({built_program("cpm"), "lab", "mark", "lap 2 begins", "--source", "planner"});
    ASSERT_EQ(second.wait(30s), 0) << second.errors();
    auto lines = [](const std::string& out) {
        std::vector<nlohmann::json> v;
        std::istringstream in(out);
        for (std::string l; std::getline(in, l);) v.push_back(nlohmann::json::parse(l));
        return v;
    };
    const Answer live = ask({"marks", "--json"});
    ASSERT_EQ(live.code, 0) << live.err;
    const auto marks = lines(live.out);
    ASSERT_EQ(marks.size(), 2u) << live.out;
    EXPECT_EQ(marks[0]["text"], "car 3 touched the wall");
    EXPECT_EQ(marks[0]["source"], "cpm lab mark");
    EXPECT_EQ(marks[1]["text"], "lap 2 begins");
    EXPECT_EQ(marks[1]["source"], "planner");
    EXPECT_LT(marks[0]["data_ns"].get<uint64_t>(), marks[1]["data_ns"].get<uint64_t>());
    // Wrong marks are refused before anything is sent; a mark nobody records is said.
    Process empty({built_program("cpm"), "lab", "mark", " "});
    EXPECT_EQ(empty.wait(30s), 2);
    EXPECT_NE(empty.errors().find("needs a text"), std::string::npos) << empty.errors();
    Process longer({built_program("cpm"), "lab", "mark", std::string(300, 'x')});
    EXPECT_EQ(longer.wait(30s), 2);
    EXPECT_NE(longer.errors().find("300 bytes; at most 256"), std::string::npos) << longer.errors();
    Process nobody({built_program("cpm"), "lab", "mark", "lost?", "--dds_domain", std::to_string(cpm_test::extra_test_domain_id())});
    EXPECT_EQ(nobody.wait(30s), 1);
    EXPECT_NE(nobody.errors().find("nobody records bookmarks"), std::string::npos) << nobody.errors();

    service.kill(SIGINT);
    ASSERT_EQ(service.wait(30s), 0) << service.errors();
    const Answer recorded = ask({"marks", "--json"}, file);
    ASSERT_EQ(recorded.code, 0) << recorded.err;
    EXPECT_EQ(recorded.out, live.out);
    const auto f = cpm::rtdb::mcap::read(file);
    std::vector<std::string> texts;
    for (const auto& m : f.metadata) {
        if (m.name == "cpm.bookmark") texts.push_back(m.values.at("text") + " / " + m.values.at("source") + " / " + m.values.at("time_ns"));
    }
    EXPECT_EQ(texts, (std::vector<std::string>{"car 3 touched the wall / cpm lab mark / " + std::to_string(marks[0]["data_ns"].get<uint64_t>()),
                                               "lap 2 begins / planner / " + std::to_string(marks[1]["data_ns"].get<uint64_t>())}));
    EXPECT_EQ(cpm_test::mcap_differences(file), "");
}

TEST(RecordingEndToEnd, ASplitRecordingReadAsOneHoldsWhatAnUnsplitOneOfTheSameRunHolds)
{
    TempDir dir;
    fs::create_directories(dir.file("parts"));
    cpm::Participant participant{udp_only()};
    cpm::HistoryClient client{participant};
    Process whole({built_program("cpm_history"), "--record", dir.file("whole.mcap")});
    Process split({built_program("cpm_history"), "--record", dir.file("parts/run.db"), "--record-split", "100kB"});
    Process cars = writer({"--type", "vehicle", "--vehicle", "3", "--count", "3000", "--readers", "2"});  // both services
    ASSERT_EQ(cars.wait(60s), 0) << cars.errors();
    whole.kill(SIGINT);
    split.kill(SIGINT);
    ASSERT_EQ(whole.wait(30s), 0) << whole.errors();
    ASSERT_EQ(split.wait(30s), 0) << split.errors();
    size_t files = 0;
    for (const auto& e : fs::directory_iterator(dir.file("parts"))) files += e.path().extension() == ".db";
    EXPECT_GE(files, 3u) << "3000 states of ~100 bytes in files of 100 kB";
    // The same samples by data time, once each (the services' own commit times differ).
    auto states = [&](const std::string& file) {
        const Answer a = ask({"range", "--topic", "vehicleState", "--key", "3", "--by", "data", "--from", std::to_string(kBase), "--to",
                              std::to_string(kBase + 3000 * kMs), "--limit", "5000", "--json"}, file);
        EXPECT_EQ(a.code, 0) << a.err;
        std::vector<std::string> out;
        std::istringstream in(a.out);
        for (std::string l; std::getline(in, l);) {
            auto j = nlohmann::json::parse(l);
            out.push_back(std::to_string(j["data_ns"].get<uint64_t>()) + " " + j["data"].dump());
        }
        return out;
    };
    const auto from_parts = states(dir.file("parts")), from_whole = states(dir.file("whole.mcap"));
    EXPECT_EQ(from_parts.size(), 3000u);
    EXPECT_EQ(from_parts, from_whole);
    EXPECT_EQ(cpm_test::mcap_differences(dir.file("whole.mcap")), "");
}

TEST(RecordingEndToEnd, AnMcapRecordingOnADiskThatFillsIsClosedValidUpToItsLastChunk)
{
    // A real full disk: a tmpfs of 256 KiB the test mounts (root here and in CI).
    if (::geteuid() != 0) GTEST_SKIP() << "mounting a small disk needs root";
    TempDir dir;
    const std::string disk = dir.file("disk");
    const cpm_test::SmallDisk small(disk, "256k");
    ASSERT_TRUE(small.mounted());
    const std::string file = disk + "/full.mcap";
    cpm::Participant participant{udp_only()};
    cpm::HistoryClient client{participant};
    Process service({built_program("cpm_history"), "--record", file});
    Process cars = writer({"--type", "vehicle", "--vehicle", "3", "--count", "1500"});
    ASSERT_EQ(cars.wait(60s), 0) << cars.errors();
    ASSERT_TRUE(wait_for_samples(client, "vehicleState", "3", 1500)) << service.errors();
    ASSERT_TRUE(cpm_test::wait_until([&] { return service.errors().find("the recording stopped") != std::string::npos; }, 20s, 20ms))
        << service.errors();
    EXPECT_NE(service.errors().find("No space left on device"), std::string::npos) << service.errors();
    EXPECT_NE(service.errors().find(file), std::string::npos) << service.errors();
    auto newest = client.latest<VehicleState>("vehicleState", 3);
    ASSERT_TRUE(newest.ok()) << "the live history goes on: " << newest.status;
    EXPECT_EQ(newest.sample.pose().x(), 1499);
    service.kill(SIGINT);
    EXPECT_EQ(service.wait(30s), 1) << service.output() << service.errors();
    // Closed valid: summary and all, the chunks before the full disk in it.
    EXPECT_EQ(cpm_test::mcap_differences(file), "");
    const Answer first = ask({"at", "--topic", "vehicleState", "--key", "3", "--by", "data", "--time", std::to_string(kBase), "--json"}, file);
    ASSERT_EQ(first.code, 0) << first.err;
    EXPECT_EQ(nlohmann::json::parse(first.out)["data"]["pose"]["x"], 0);
    EXPECT_EQ(first.err, "") << "a whole file";
}
