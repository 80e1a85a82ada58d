// The IDL reader behind `cpm history --json` and recordings: IDL text as a recording carries it
// (idl_text), and sample bytes decoded with the lab's own types (idl_decode). A sample that
// decodes must encode back to bytes that decode to the same JSON.
#include "../Fuzz.hpp"

#include <cpm/Error.hpp>
#include <cpm/rtdb/IdlDecoder.hpp>

CPM_FUZZ_TARGET(idl_text)
{
    try {
        const cpm::rtdb::IdlDecoder types({{"fuzz.idl", cpm::fuzz::text(data, size)}});
        for (const auto& [file, text] : types.sources()) (void)file, (void)text;
    } catch (const cpm::Error& e) {  // anything else escapes: a defect
        cpm::fuzz::expect(std::string(e.what()).find("fuzz.idl") != std::string::npos, "an IDL error that does not name the file");
    }
    return 0;
}

CPM_FUZZ_TARGET(idl_decode)
{
    // The first byte picks one of the lab's types; the rest is the sample as it came off the wire.
    static const cpm::rtdb::IdlDecoder* types = cpm::rtdb::IdlDecoder::lab_types();
    static const std::vector<std::string> names = {
        "VehicleState", "VehicleObservation", "VehicleCommandDirect", "VehicleCommandSpeedCurvature",
        "VehicleCommandTrajectory", "VehicleCommandPathTracking", "RangeSensors", "ArucoMarkers",
        "FsmStatus", "Parameter", "ParameterRequest", "HistoryRequest", "HistoryReply", "HistoryStatus", "Log",
        "LogLevel", "ReadyStatus", "SystemTrigger", "StopRequest", "CameraFrame"};
    cpm::fuzz::expect(types != nullptr, "the lab's IDL folder cannot be read (CPM_IDL_DIR)");
    if (size == 0) return 0;
    const std::string& type = names[data[0] % names.size()];
    const std::vector<uint8_t> payload(data + 1, data + size);
    (void)types->key_text(type, payload.data(), payload.size());
    (void)types->key_bytes(type, payload.data(), payload.size());
    (void)types->describe(type, payload);
    const auto json = types->decode(type, payload);
    if (!json) return 0;
    try {
        const auto again = types->decode(type, types->encode(type, *json));
        cpm::fuzz::expect(again && again->dump() == json->dump(), "decode(encode(decode(x))) != decode(x)");
    } catch (const cpm::Error& e) {
        // What decode shows but encode rightly refuses: NaN (not JSON, shown as null) and an enum
        // value the IDL does not list (shown as its number).
        const std::string why = e.what();
        cpm::fuzz::expect(json->dump().find("null") != std::string::npos || why.find(" is no ") != std::string::npos, e.what());
    }
    return 0;
}
