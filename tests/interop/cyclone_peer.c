/* A foreign DDS peer built with Cyclone DDS from the same IDL files as cpm.
 *
 *   cyclone_peer pub COUNT ID...   waits for a reader, writes COUNT VehicleState samples per
 *                                  vehicle id (create_stamp = 1000*k + id, valid_after =
 *                                  create + 60, pose.x = k), waits for acknowledgements.
 *   cyclone_peer sub COUNT         prints "vehicle create valid_after x" for each sample
 *                                  until COUNT arrived; exits 0, or 3 after 20 s.
 *
 * Both sides are reliable, keep-all and transient-local. Domain from CPM_DOMAIN_ID; transport settings from CYCLONEDDS_URI (the test pins it to
 * loopback with unicast discovery).
 */
#include "VehicleState.h"

#include <dds/dds.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static dds_entity_t make_topic(dds_entity_t participant)
{
    const char* topic = getenv("CPM_INTEROP_TOPIC");
    return dds_create_topic(participant, &VehicleState_desc, topic ? topic : "vehicleState", NULL, NULL);
}

/* Reliable, keep-all, transient-local: a reader that matches after the writer wrote still
 * gets everything (a volatile one may legitimately skip what came before its match). */
static dds_qos_t* reliable_qos(void)
{
    dds_qos_t* qos = dds_create_qos();
    dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
    dds_qset_history(qos, DDS_HISTORY_KEEP_ALL, 0);
    dds_qset_durability(qos, DDS_DURABILITY_TRANSIENT_LOCAL);
    return qos;
}

static int publish(dds_entity_t participant, int count, int n_ids, char** ids)
{
    dds_qos_t* qos = reliable_qos();
    dds_entity_t writer = dds_create_writer(participant, make_topic(participant), qos, NULL);
    dds_delete_qos(qos);
    if (writer < 0) return 2;

    dds_publication_matched_status_t status = {0};
    for (int waited = 0; status.current_count == 0; waited += 10) {
        if (waited > 20000) { fprintf(stderr, "cyclone_peer: no reader matched\n"); return 3; }
        dds_sleepfor(DDS_MSECS(10));
        dds_get_publication_matched_status(writer, &status);
    }
    for (int k = 0; k < count; ++k) {
        for (int i = 0; i < n_ids; ++i) {
            VehicleState s;
            memset(&s, 0, sizeof s);
            s.vehicle_id = (uint8_t)atoi(ids[i]);
            s.header.create_stamp.nanoseconds = 1000ull * (unsigned)k + s.vehicle_id;
            s.header.valid_after_stamp.nanoseconds = s.header.create_stamp.nanoseconds + 60;
            s.pose.x = k;
            s.speed = 0.5 * s.vehicle_id;
            if (dds_write(writer, &s) != DDS_RETCODE_OK) return 4;
        }
    }
    return dds_wait_for_acks(writer, DDS_SECS(10)) == DDS_RETCODE_OK ? 0 : 5;
}

static int subscribe(dds_entity_t participant, int count)
{
    dds_qos_t* qos = reliable_qos();
    dds_entity_t reader = dds_create_reader(participant, make_topic(participant), qos, NULL);
    dds_delete_qos(qos);
    if (reader < 0) return 2;
    printf("ready\n");
    fflush(stdout);

    int received = 0;
    for (int waited = 0; received < count; waited += 5) {
        if (waited > 20000) return 3;
        void* samples[16] = {NULL};
        dds_sample_info_t infos[16];
        const int n = dds_take(reader, samples, infos, 16, 16);
        for (int i = 0; i < n; ++i) {
            if (!infos[i].valid_data) continue;
            const VehicleState* s = samples[i];
            printf("%u %llu %llu %g\n", (unsigned)s->vehicle_id,
                   (unsigned long long)s->header.create_stamp.nanoseconds,
                   (unsigned long long)s->header.valid_after_stamp.nanoseconds, s->pose.x);
            ++received;
        }
        if (n > 0) dds_return_loan(reader, samples, n);
        fflush(stdout);
        if (n <= 0) dds_sleepfor(DDS_MSECS(5));
    }
    return 0;
}

int main(int argc, char** argv)
{
    if (argc < 3 || (strcmp(argv[1], "pub") != 0 && strcmp(argv[1], "sub") != 0)) {
        fprintf(stderr, "usage: cyclone_peer pub COUNT ID... | cyclone_peer sub COUNT\n");
        return 1;
    }
    const char* domain = getenv("CPM_DOMAIN_ID");
    dds_entity_t participant = dds_create_participant(domain ? (dds_domainid_t)atoi(domain) : 0, NULL, NULL);
    if (participant < 0) {
        fprintf(stderr, "cyclone_peer: cannot create participant: %s\n", dds_strretcode(-participant));
        return 2;
    }
    const int count = atoi(argv[2]);
    const int rc = strcmp(argv[1], "pub") == 0 ? publish(participant, count, argc - 3, argv + 3)
                                                : subscribe(participant, count);
    dds_delete(participant);
    return rc;
}
