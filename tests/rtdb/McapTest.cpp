// cpm's MCAP writer and reader: a file written with several channels and chunks reads back
// message for message, with every CRC checked and the summary a viewer seeks with (a Chunk Index
// per chunk, a Message Index per channel and chunk, Statistics); damage is named with its offset.
#include <cpm/Error.hpp>
#include <cpm/rtdb/Mcap.hpp>

#include <cpm_test/TempDir.hpp>

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>

#include <cerrno>
#include <cstring>
#include <unistd.h>

namespace {

namespace mcap = cpm::rtdb::mcap;

TEST(Mcap, Crc32IsZlibs)
{
    const std::string text = "123456789";
    EXPECT_EQ(mcap::crc32(reinterpret_cast<const uint8_t*>(text.data()), text.size()), 0xCBF43926u);  // the CRC-32 check value
    EXPECT_EQ(mcap::crc32(nullptr, 0), 0u);
}

TEST(Mcap, AFileOfTwoChannelsAndManyChunksReadsBackMessageForMessage)
{
    cpm_test::TempDir dir;
    const std::string path = dir.file("run.mcap");
    {
        mcap::Writer w(path, "cpm test", 300);  // small chunks: many of them
        const auto state = w.add_schema("VehicleState", "omgidl", "struct VehicleState { double speed; };");
        const auto log = w.add_schema("Log", "omgidl", "struct Log { string content; };");
        const auto a = w.add_channel(state, "vehicleState", "cdr", {{"cpm.keyed", "true"}, {"cpm.type", "VehicleState"}});
        const auto b = w.add_channel(log, "log", "cdr");
        for (uint8_t i = 0; i < 50; ++i) {
            const std::vector<uint8_t> payload{0, 1, 0, 0, i, uint8_t(i * 3)};
            w.write(i % 5 == 0 ? b : a, 1000 + i, 900 + i, payload.data(), payload.size());
        }
        w.add_metadata("cpm.run", {{"scenario", "name: x"}, {"summary", "{}"}});
        EXPECT_EQ(w.messages(), 50u);
        w.close();
    }
    const auto f = mcap::read(path);
    EXPECT_EQ(f.profile, "");
    EXPECT_EQ(f.library, "cpm test");
    ASSERT_EQ(f.schemas.size(), 2u);
    EXPECT_EQ(f.schemas.at(1).name, "VehicleState");
    EXPECT_EQ(f.schemas.at(1).encoding, "omgidl");
    EXPECT_EQ(f.schemas.at(2).data, "struct Log { string content; };");
    ASSERT_EQ(f.channels.size(), 2u);
    EXPECT_EQ(f.channels.at(0).topic, "vehicleState");
    EXPECT_EQ(f.channels.at(0).metadata.at("cpm.keyed"), "true");
    EXPECT_EQ(f.channels.at(1).message_encoding, "cdr");
    ASSERT_EQ(f.messages.size(), 50u);
    uint32_t seq_a = 0, seq_b = 0;
    for (uint8_t i = 0; i < 50; ++i) {
        const auto& m = f.messages[i];
        EXPECT_EQ(m.channel_id, i % 5 == 0 ? 1 : 0);
        EXPECT_EQ(m.sequence, i % 5 == 0 ? seq_b++ : seq_a++) << "a sequence number per channel";
        EXPECT_EQ(m.log_time, 1000u + i);
        EXPECT_EQ(m.publish_time, 900u + i);
        EXPECT_EQ(m.data, (std::vector<uint8_t>{0, 1, 0, 0, i, uint8_t(i * 3)}));
    }
    EXPECT_GT(f.chunk_count, 5u);
    EXPECT_EQ(f.chunk_indexes, f.chunk_count) << "a Chunk Index per chunk in the summary";
    EXPECT_GE(f.message_indexes, f.chunk_count) << "a Message Index per channel after each chunk";
    EXPECT_GT(f.summary_start, 0u);
    EXPECT_EQ(f.statistics_messages, 50u);
    EXPECT_EQ(f.statistics_channel_counts, (std::map<uint16_t, uint64_t>{{0, 40}, {1, 10}}));
    ASSERT_EQ(f.metadata.size(), 1u);
    EXPECT_EQ(f.metadata[0].name, "cpm.run");
    EXPECT_EQ(f.metadata[0].values.at("scenario"), "name: x");
}

TEST(Mcap, DamageIsNamedWithItsOffsetAndAnExistingFileIsNeverOverwritten)
{
    cpm_test::TempDir dir;
    const std::string path = dir.file("run.mcap");
    {
        mcap::Writer w(path, "cpm test");
        const auto c = w.add_channel(w.add_schema("T", "omgidl", "struct T { long x; };"), "t", "cdr");
        const std::vector<uint8_t> payload(64, 7);
        w.write(c, 1, 1, payload.data(), payload.size());
    }  // closed by its destructor
    EXPECT_THROW(mcap::Writer(path, "again"), cpm::Error);
    std::ifstream in(path, std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), {});
    EXPECT_EQ(mcap::read(path).messages.size(), 1u);

    std::string flipped = bytes;
    flipped[120] = char(flipped[120] ^ 0x40);  // inside the chunk's records
    std::ofstream(dir.file("flipped.mcap"), std::ios::binary) << flipped;
    try {
        (void)mcap::read(dir.file("flipped.mcap"));
        FAIL() << "a flipped bit went unnoticed";
    } catch (const cpm::Error& e) {
        EXPECT_NE(std::string(e.what()).find("CRC does not match"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("flipped.mcap: at byte"), std::string::npos) << e.what();
    }
    std::ofstream(dir.file("cut.mcap"), std::ios::binary) << bytes.substr(0, bytes.size() / 2);
    try {
        (void)mcap::read(dir.file("cut.mcap"));
        FAIL() << "a file cut in half went unnoticed";
    } catch (const cpm::Error& e) {
        EXPECT_NE(std::string(e.what()).find("no closing magic"), std::string::npos) << e.what();
    }
    std::ofstream(dir.file("not.mcap")) << "hello, this is not a recording";
    EXPECT_THROW((void)mcap::read(dir.file("not.mcap")), cpm::Error);
}

TEST(Mcap, PrivateRecordsAndSequenceGapsReadBackWhereTheyWereWritten)
{
    cpm_test::TempDir dir;
    const std::string path = dir.file("private.mcap");
    {
        mcap::Writer w(path, "cpm test", 200);
        const auto c = w.add_channel(w.add_schema("T", "omgidl", "struct T { long x; };"), "t", "cdr");
        const auto raw = w.add_channel(0, "unknown", "cdr");  // a type without a schema
        EXPECT_THROW(w.write_private(0x0C, "x"), cpm::Error) << "0x0C is the spec's Metadata";
        for (uint8_t i = 0; i < 20; ++i) {
            w.write_private(0x81, std::string(1, char(i)));
            const std::vector<uint8_t> payload{0, 1, 0, 0, i, 0, 0, 0};
            w.write(i % 4 == 3 ? raw : c, 10 + i, 10 + i, payload.data(), payload.size(), i == 10 ? std::optional<uint32_t>(100) : std::nullopt);
        }
    }
    const auto f = mcap::read(path);
    ASSERT_EQ(f.messages.size(), 20u);
    ASSERT_EQ(f.privates.size(), 20u);
    for (size_t i = 0; i < 20; ++i) {
        EXPECT_EQ(f.privates[i].op, 0x81);
        EXPECT_EQ(f.privates[i].body, std::string(1, char(i)));
        EXPECT_EQ(f.privates[i].before_message, i) << "each before the message written after it";
    }
    EXPECT_EQ(f.channels.at(1).schema_id, 0);
    EXPECT_EQ(f.messages[9].sequence, 7u);   // channel t's eighth message
    EXPECT_EQ(f.messages[10].sequence, 100u) << "a sequence given";
    EXPECT_EQ(f.messages[12].sequence, 101u) << "and counted on from there";
}

TEST(Mcap, AFileCutShortReadsItsWholeChunksAndNamesWhereItStopped)
{
    cpm_test::TempDir dir;
    const std::string path = dir.file("killed.mcap");
    std::string bytes;
    std::vector<size_t> chunk_ends;  // the file's size after each flush
    {
        mcap::Writer w(path, "cpm test", 1 << 20);
        const auto c = w.add_channel(w.add_schema("T", "omgidl", "struct T { long x; };"), "t", "cdr");
        for (uint8_t i = 0; i < 30; ++i) {
            const std::vector<uint8_t> payload(40, i);
            w.write(c, 100 + i, 100 + i, payload.data(), payload.size());
            if (i % 10 == 9) {
                w.flush();  // as the recorder does once a second
                chunk_ends.push_back(std::filesystem::file_size(path));
            }
        }
        std::ifstream in(path, std::ios::binary);
        bytes.assign((std::istreambuf_iterator<char>(in)), {});  // the file as a SIGKILL would leave it
    }
    ASSERT_EQ(bytes.size(), chunk_ends.back());
    std::ofstream(dir.file("unfinished.mcap"), std::ios::binary) << bytes;
    EXPECT_THROW((void)mcap::read(dir.file("unfinished.mcap")), cpm::Error) << "refused unless damage is asked to be kept";
    const auto whole = mcap::read(dir.file("unfinished.mcap"), mcap::Damage::keep_what_reads);
    EXPECT_EQ(whole.messages.size(), 30u);
    EXPECT_NE(whole.damage.find("not finished"), std::string::npos) << whole.damage;
    // Cut inside the third chunk: the first two read, the third not at all.
    std::ofstream(dir.file("cut.mcap"), std::ios::binary) << bytes.substr(0, chunk_ends[1] + 30);
    const auto cut = mcap::read(dir.file("cut.mcap"), mcap::Damage::keep_what_reads);
    EXPECT_EQ(cut.messages.size(), 20u);
    EXPECT_EQ(cut.messages.back().log_time, 119u);
    EXPECT_NE(cut.damage.find("at byte " + std::to_string(chunk_ends[1])), std::string::npos) << cut.damage << " (chunk ends " << chunk_ends[0] << ", " << chunk_ends[1] << ")";
    EXPECT_NE(cut.damage.find("30 bytes from there on are not read"), std::string::npos) << cut.damage;
}

TEST(Mcap, AChunkPastTheSizeLimitIsRefusedAndTheFileClosesValidWithoutIt)
{
    cpm_test::TempDir dir;
    const std::string path = dir.file("capped.mcap");
    mcap::Writer w(path, "cpm test", 4096, 100 * 1024);
    const auto c = w.add_channel(w.add_schema("T", "omgidl", "struct T { long x; };"), "t", "cdr");
    const std::vector<uint8_t> payload(1000, 1);
    uint64_t refused_at = 0;
    for (uint64_t i = 0; i < 1000 && !refused_at; ++i) {
        try {
            w.write(c, i, i, payload.data(), payload.size());
        } catch (const cpm::Error& e) {
            EXPECT_NE(std::string(e.what()).find("size limit of 102400 bytes"), std::string::npos) << e.what();
            refused_at = i + 1;
        }
    }
    ASSERT_GT(refused_at, 0u) << "100 KiB cannot hold a thousand samples of 1000 bytes";
    const uint64_t kept = w.messages();
    EXPECT_GT(kept, 10u);
    EXPECT_LT(kept, refused_at);
    w.close();
    EXPECT_LE(std::filesystem::file_size(path), 100u * 1024);
    const auto f = mcap::read(path);
    EXPECT_EQ(f.messages.size(), kept);
    EXPECT_EQ(f.statistics_messages, kept) << "the statistics count what is in the file";
}

// A real full disk (a 64 KiB tmpfs; root here and in CI): the chunk that does not fit is refused
// and the file still closes with its summary, although the summary (a schema of 6 KB) is larger
// than what the disk had left after the last chunk: the writer keeps room for it as it goes.
TEST(Mcap, AFullDiskRefusesTheChunkThatDoesNotFitAndTheFileClosesValidWithEveryOneBefore)
{
    if (::geteuid() != 0) GTEST_SKIP() << "mounting a small disk needs root";
    cpm_test::TempDir dir;
    const std::string disk = dir.file("disk");
    const cpm_test::SmallDisk small(disk, "64k");
    ASSERT_TRUE(small.mounted());
    const std::string path = disk + "/full.mcap";
    uint64_t kept = 0;
    {
        mcap::Writer w(path, "cpm test", 4096);
        const auto c = w.add_channel(w.add_schema("T", "omgidl", "struct T { long x; };" + std::string(6000, ' ')), "t", "cdr");
        const std::vector<uint8_t> payload(1000, 1);
        bool refused = false;
        for (uint64_t i = 0; i < 1000 && !refused; ++i) {
            try {
                w.write(c, i, i, payload.data(), payload.size());
            } catch (const cpm::Error& e) {
                EXPECT_NE(std::string(e.what()).find(std::strerror(ENOSPC)), std::string::npos) << e.what();
                refused = true;
            }
        }
        ASSERT_TRUE(refused) << "64 KiB cannot hold a thousand samples of 1000 bytes";
        kept = w.messages();
        EXPECT_GT(kept, 5u);  // a chunk of about 7 KB each (the schema in each)
        EXPECT_NO_THROW(w.close());
    }
    const auto f = mcap::read(path);
    EXPECT_EQ(f.messages.size(), kept);
    EXPECT_EQ(f.statistics_messages, kept);
}

}  // namespace
