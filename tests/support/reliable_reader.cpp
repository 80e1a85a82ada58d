// A test helper: a reliable, keep-all VehicleState reader in its own process that prints
// "matched" once a writer matched, then takes (and acknowledges) whatever arrives until killed.
//   reliable_reader TOPIC        (domain from CPM_DOMAIN_ID)
#include <cpm/ReaderAbstract.hpp>
#include <cpm/init.hpp>

#include <VehicleState.h>

#include <chrono>
#include <cstdio>

int main(int argc, char** argv)
{
    if (argc < 2) {
        std::fprintf(stderr, "usage: reliable_reader TOPIC\n");
        return 2;
    }
    cpm::init(argc, argv);
    cpm::ReaderOptions options;
    options.reliable = true;
    options.keep_all = true;
    cpm::ReaderAbstract<VehicleState> reader(argv[1], options);
    if (!reader.wait_for_matched(1, std::chrono::seconds(20))) return 3;
    std::printf("matched\n");
    std::fflush(stdout);
    for (;;) {
        if (reader.wait_for_data(std::chrono::milliseconds(100))) reader.take();
    }
}
