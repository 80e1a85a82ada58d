// cpm's compiled Python module (cpm._cpm): the lab's message types and their typed readers and
// writers (generated from the IDL), init, time, participants, logging, the Timer and the HLC
// Communicator. The Python package (python/cpm/) gives them their Python shape.
#include "cpm_py.hpp"

#include <cpm/Error.hpp>
#include <cpm/HistoryClient.hpp>
#include <cpm/Timer.hpp>
#include <cpm/get_parameter.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/hlc/Communicator.hpp>
#include <cpm/init.hpp>

#include <pybind11/stl.h>

#include <HistoryReply.h>
#include <HistoryRequest.h>

namespace py = pybind11;

void cpm_py_bind_types(py::module_& m);
void cpm_py_bind_topics(py::module_& m);

namespace {

/// Asked while C++ waits with the GIL released: takes the GIL, lets Python run its signal
/// handlers (Ctrl-C raises KeyboardInterrupt there) and says whether one raised.
struct SignalWatch
{
    bool raised = false;
    bool operator()()
    {
        py::gil_scoped_acquire gil;
        if (PyErr_CheckSignals() != 0) raised = true;
        return raised;
    }
};

/// A Python callback called from C++ with the GIL; its exception becomes a cpm::Error carrying
/// the Python traceback (the Communicator logs it and counts the step failed).
template <class... Args>
std::function<void(Args...)> from_python(py::function f, const char* what)
{
    auto shared = cpm_py::keep(std::move(f));
    return [shared, what](Args... args) {
        cpm_py::CallbackGil gil;
        try {
            (*shared)(args...);
        } catch (py::error_already_set& e) {
            throw cpm::Error(std::string(what) + " raised " + e.what());
        }
    };
}

/// The HLC Communicator with the watch its start() asks for Ctrl-C.
struct HlcCommunicator
{
    std::shared_ptr<SignalWatch> watch;
    std::unique_ptr<cpm::hlc::Communicator> hlc;
    ~HlcCommunicator()
    {
        if (!hlc || !PyGILState_Check()) return;  // moved from, or made where the GIL is released
        py::gil_scoped_release release;           // its threads may be waiting for the GIL
        hlc.reset();
    }
    HlcCommunicator(std::shared_ptr<SignalWatch> w, std::unique_ptr<cpm::hlc::Communicator> c) : watch(std::move(w)), hlc(std::move(c)) {}
    HlcCommunicator(HlcCommunicator&&) = default;
};

/// cpm::init, the clock, the log and the lab's parameters.
void bind_process(py::module_& m)
{
    m.def("init", [](std::vector<std::string> argv) {
        std::vector<char*> args;
        for (auto& a : argv) args.push_back(a.data());
        cpm::init(int(args.size()), args.data());
    }, py::arg("argv"));
    m.def("get_time_ns", &cpm::get_time_ns);
    m.def("simulated_time", [] { return cpm::init_settings().simulated_time; });
    m.def("domain_id", [] { return cpm::init_settings().domain_id; });
    m.def("log", [](int level, const std::string& text) {
        if (level < 1 || level > 4) throw py::value_error("log level " + std::to_string(level) + " is not 1 (error) .. 4 (debug)");
        cpm::Logging::instance().write(cpm::Severity(level), "%s", text.c_str());
    });

    // The lab's parameters (cpm param serve): blocking reads, the GIL released while they wait.
    auto parameter = [&m](const char* name, auto getter) {
        m.def(name, [getter](const std::string& p, double timeout_s) {
            py::gil_scoped_release release;
            return getter(p, std::chrono::milliseconds(int64_t(timeout_s * 1000)));
        }, py::arg("name"), py::arg("timeout_s") = 5.0);
    };
    parameter("parameter_bool", [](const std::string& p, std::chrono::milliseconds t) { return cpm::parameter_bool(p, t); });
    parameter("parameter_int", [](const std::string& p, std::chrono::milliseconds t) { return cpm::parameter_int(p, t); });
    parameter("parameter_uint64_t", [](const std::string& p, std::chrono::milliseconds t) { return cpm::parameter_uint64_t(p, t); });
    parameter("parameter_double", [](const std::string& p, std::chrono::milliseconds t) { return cpm::parameter_double(p, t); });
    parameter("parameter_string", [](const std::string& p, std::chrono::milliseconds t) { return cpm::parameter_string(p, t); });
    parameter("parameter_ints", [](const std::string& p, std::chrono::milliseconds t) { return cpm::parameter_ints(p, t); });
    parameter("parameter_doubles", [](const std::string& p, std::chrono::milliseconds t) { return cpm::parameter_doubles(p, t); });
}

/// Participants and the options of readers and writers.
void bind_participant(py::module_& m)
{
    py::class_<cpm::Participant>(m, "Participant")
        .def(py::init([](int domain_id, const std::string& name) {
                 cpm::ParticipantOptions o = cpm::ParticipantOptions::from_init();
                 if (domain_id >= 0) o.domain_id = domain_id;
                 if (!name.empty()) o.name = name;
                 py::gil_scoped_release release;
                 return std::make_unique<cpm::Participant>(o);
             }),
             py::arg("domain_id") = -1, py::arg("name") = "")
        .def_property_readonly("domain_id", &cpm::Participant::domain_id);

    py::class_<cpm::WriterOptions>(m, "WriterOptions")
        .def(py::init<>())
        .def_readwrite("reliable", &cpm::WriterOptions::reliable)
        .def_readwrite("keep_all", &cpm::WriterOptions::keep_all)
        .def_readwrite("history_depth", &cpm::WriterOptions::history_depth)
        .def_readwrite("transient_local", &cpm::WriterOptions::transient_local)
        .def_readwrite("max_unacknowledged", &cpm::WriterOptions::max_unacknowledged)
        .def_readwrite("data_sharing", &cpm::WriterOptions::data_sharing);
    py::class_<cpm::ReaderOptions>(m, "ReaderOptions")
        .def(py::init<>())
        .def_readwrite("reliable", &cpm::ReaderOptions::reliable)
        .def_readwrite("keep_all", &cpm::ReaderOptions::keep_all)
        .def_readwrite("history_depth", &cpm::ReaderOptions::history_depth)
        .def_readwrite("transient_local", &cpm::ReaderOptions::transient_local)
        .def_readwrite("buffer_capacity", &cpm::ReaderOptions::buffer_capacity)
        .def_readwrite("vehicle_id", &cpm::ReaderOptions::vehicle_id)
        .def_readwrite("data_sharing", &cpm::ReaderOptions::data_sharing);
}

/// The history client, live or from a recording.
void bind_history(py::module_& m)
{
    py::class_<cpm::HistoryClient>(m, "HistoryClient")
        .def(py::init([](cpm::Participant* p, double reply_timeout_s) {
                 py::gil_scoped_release release;
                 return std::make_unique<cpm::HistoryClient>(cpm_py::participant_of(p), std::chrono::milliseconds(int64_t(reply_timeout_s * 1000)));
             }),
             py::arg("participant") = nullptr, py::arg("reply_timeout_s") = 3.0, py::keep_alive<1, 2>())
        .def_static("open_recording", [](const std::string& path) {
            py::gil_scoped_release release;
            return std::make_unique<cpm::HistoryClient>(cpm::HistoryClient::open_recording(path));
        })
        .def("request", [](cpm::HistoryClient& c, const HistoryRequest& rq) {
            py::gil_scoped_release release;
            return c.request(rq);
        });
}

/// cpm::Timer: its callback in Python, Ctrl-C ends start().
void bind_timer(py::module_& m)
{
    py::class_<cpm::Timer, std::shared_ptr<cpm::Timer>>(m, "Timer")
        .def(py::init([](const std::string& node_id, uint64_t period_ns, uint64_t offset_ns, bool wait_for_start, bool simulated_time_allowed,
                         const py::object& realtime) {
                 cpm::TimerOptions options{wait_for_start, simulated_time_allowed};
                 // None: cpm.init's --realtime; True/False; or "on", "off", "required".
                 if (py::isinstance<py::bool_>(realtime)) options.realtime = realtime.cast<bool>() ? cpm::Realtime::on : cpm::Realtime::off;
                 else if (!realtime.is_none()) options.realtime = cpm::parse_realtime(py::str(realtime).cast<std::string>(), "Timer realtime");
                 py::gil_scoped_release release;
                 return cpm::Timer::create(node_id, period_ns, offset_ns, options);
             }),
             py::arg("node_id"), py::arg("period_ns"), py::arg("offset_ns") = 0, py::arg("wait_for_start") = true,
             py::arg("simulated_time_allowed") = true, py::arg("realtime") = py::none())
        .def("start", [](cpm::Timer& t, py::function callback) {
            auto cb = from_python<uint64_t>(std::move(callback), "the timer's callback");
            SignalWatch watch;
            std::string error;
            {
                py::gil_scoped_release release;
                t.run_until(std::ref(watch), [&](uint64_t tick) {
                    try {
                        cb(tick);
                    } catch (const std::exception& e) {
                        error = e.what();
                        t.stop();
                    }
                });
            }
            if (watch.raised) throw py::error_already_set();
            if (!error.empty()) throw cpm::Error(error);
        })
        .def("stop", [](cpm::Timer& t) { t.stop(); })
        .def_property_readonly("start_time", &cpm::Timer::start_time)
        .def_property_readonly("missed_deadlines", &cpm::Timer::missed_deadlines)
        .def_property_readonly("period_ns", &cpm::Timer::period_ns);
}

/// cpm::hlc::Communicator: a controller in Python.
void bind_hlc(py::module_& m)
{
    py::class_<HlcCommunicator>(m, "HlcCommunicator")
        .def(py::init([](std::vector<uint8_t> ids, cpm::Participant* p) {
                 auto watch = std::make_shared<SignalWatch>();
                 cpm::hlc::CommunicatorOptions o{.participant = p, .stop_requested = [watch] { return (*watch)(); }};
                 py::gil_scoped_release release;
                 return std::make_unique<HlcCommunicator>(HlcCommunicator{watch, std::make_unique<cpm::hlc::Communicator>(std::move(ids), o)});
             }),
             py::arg("vehicle_ids"), py::arg("participant") = nullptr, py::keep_alive<1, 3>())
        .def("on_first_timestep", [](HlcCommunicator& c, py::function f) {
            c.hlc->on_first_timestep(from_python<const VehicleStateList&>(std::move(f), "on_first_timestep"));
        })
        .def("on_each_timestep", [](HlcCommunicator& c, py::function f) {
            c.hlc->on_each_timestep(from_python<const VehicleStateList&>(std::move(f), "on_each_timestep"));
        })
        .def("on_cancel_timestep", [](HlcCommunicator& c, py::function f) { c.hlc->on_cancel_timestep(from_python<>(std::move(f), "on_cancel_timestep")); })
        .def("on_stop", [](HlcCommunicator& c, py::function f) { c.hlc->on_stop(from_python<>(std::move(f), "on_stop")); })
        .def("start", [](HlcCommunicator& c) {
            {
                py::gil_scoped_release release;
                c.hlc->start();  // asks the watch every 50 ms on this thread: Python's signal handlers run
            }
            if (c.watch->raised) throw py::error_already_set();  // KeyboardInterrupt
        })
        .def("stop", [](HlcCommunicator& c) { c.hlc->stop(); })
        .def_property_readonly("vehicle_ids", [](const HlcCommunicator& c) { return c.hlc->vehicle_ids(); })
        .def_property_readonly("steps", [](const HlcCommunicator& c) { return c.hlc->steps(); })
        .def_property_readonly("cancelled_steps", [](const HlcCommunicator& c) { return c.hlc->cancelled_steps(); })
        .def_property_readonly("failed_steps", [](const HlcCommunicator& c) { return c.hlc->failed_steps(); });
}

}  // namespace

PYBIND11_MODULE(_cpm, m)
{
    m.doc() = "cpm's compiled core; use the package: import cpm";
    py::register_exception<cpm::Error>(m, "Error", PyExc_RuntimeError);
    cpm_py_bind_types(m);
    bind_process(m);
    bind_participant(m);
    cpm_py_bind_topics(m);
    bind_history(m);
    bind_timer(m);
    bind_hlc(m);
}
