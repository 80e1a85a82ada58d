// Writer and ReaderAbstract move (the DDS entity goes along and keeps working); Reader,
// MultiVehicleReader and AsyncReader say at compile time that they do not.
#include <cpm/AsyncReader.hpp>
#include <cpm/MultiVehicleReader.hpp>
#include <cpm/Reader.hpp>
#include <cpm/ReaderAbstract.hpp>
#include <cpm/Writer.hpp>

#include <cpm_test/Dds.hpp>
#include <cpm_test/Isolation.hpp>

#include <VehicleState.h>

#include <gtest/gtest.h>

#include <type_traits>
#include <vector>

using namespace std::chrono_literals;

static_assert(std::is_nothrow_move_constructible_v<cpm::Writer<VehicleState>>);
static_assert(std::is_nothrow_move_assignable_v<cpm::Writer<VehicleState>>);
static_assert(std::is_nothrow_move_constructible_v<cpm::ReaderAbstract<VehicleState>>);
static_assert(!std::is_copy_constructible_v<cpm::Writer<VehicleState>>);
static_assert(!std::is_move_constructible_v<cpm::Reader<VehicleState>>);
static_assert(!std::is_move_constructible_v<cpm::MultiVehicleReader<VehicleState>>);
static_assert(!std::is_move_constructible_v<cpm::AsyncReader<VehicleState>>);

TEST(Move, AMovedWriterAndReaderKeepTheirDdsEntitiesAndAVectorHoldsThem)
{
    cpm::Participant participant(cpm_test::isolated_options());
    std::vector<cpm::Writer<VehicleState>> writers;
    for (int i = 0; i < 3; ++i) writers.emplace_back(participant, "moveTest", cpm::WriterOptions{.reliable = true, .history_depth = 10});
    cpm::ReaderAbstract<VehicleState> first(participant, "moveTest", {.reliable = true, .keep_all = true});
    cpm::ReaderAbstract<VehicleState> reader = std::move(first);
    ASSERT_TRUE(reader.wait_for_matched(3, 5s));
    for (auto& w : writers) ASSERT_TRUE(w.wait_for_matched(1, 5s));

    cpm::Writer<VehicleState> moved = std::move(writers[1]);
    VehicleState s;
    s.vehicle_id(2);
    ASSERT_TRUE(moved.write(s));
    std::vector<VehicleState> got;
    ASSERT_TRUE(cpm_test::wait_until([&] {
        for (auto& x : reader.take()) got.push_back(x);
        return !got.empty();
    }, 5s));
    EXPECT_EQ(got[0].vehicle_id(), 2);
    // Assigning over a writer closes the one it held: two remain matched.
    writers[0] = std::move(moved);
    EXPECT_TRUE(cpm_test::wait_until([&] { return reader.matched_publications() == 2; }, 5s)) << reader.matched_publications();
}
