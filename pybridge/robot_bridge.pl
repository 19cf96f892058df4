:- module(robot_bridge,
          [ get_qtable/2,               % deprecated: read_table/2
            get_qtable/3,               % deprecated: read_table/3
            set_qtable/2,               % deprecated: write_table/2
            set_qtable/3,               % deprecated: write_table/3
            get_visits/2,               % deprecated: read_visits/2
            get_visits/3,               % deprecated: read_visits/3
            get_qtable_and_visits/3,    % deprecated: read_table_and_visits/3
            get_qtable_and_visits/4,    % deprecated: read_table_and_visits/4
            get_params/2,               % deprecated: read_params/2
            get_params/3,               % deprecated: read_params/3
            set_params/2,               % deprecated: write_params/2
            set_params/3,               % deprecated: write_params/3
            bridge_shutdown/0
          ]).
:- reexport(bridge_registry,            % the robots and the codec
            [ bridge_register_robot/2, bridge_unregister_robot/1, bridge_robot/2,
              bridge_set_codec/1, bridge_codec/1 ]).
:- reexport(bridge_tables,              % the table and parameter API
            [ read_table/2, read_table/3, write_table/2, write_table/3,
              read_visits/2, read_visits/3, read_table_and_visits/3,
              read_table_and_visits/4, read_params/2, read_params/3,
              write_params/2, write_params/3 ]).
:- reexport(bridge_queue,               % the request queue
            [ bridge_next_request/2, bridge_service_call/3,
              bridge_next_service_request/2, bridge_reply/2, bridge_attach_server/0,
              bridge_detach_server/0, bridge_stop_threads/2, bridge_stop_threads/3 ]).
:- use_module(bridge_queue, [bridge_call/5, queue_shutdown/0]).
:- use_module(bridge_registry, [bridge_forget_robots/0]).
:- use_module('../platform_pl/robot_resources', []).

/** <module> Robot tables and parameters for agents, served by the Python host between control steps

A robot process is one Python process that embeds SWI-Prolog. Its control loop
registers each robot with bridge_register_robot/2 and, once per control
step, serves the requests that agents have queued (bridge_next_request/2 and
bridge_reply/2, called from the Python main thread by `pybridge`).

Agents, running in their own Prolog threads, call read_table/3,
write_table/3 and read_visits/3. These never call Python: they post a
request on the message queue `robot_bridge_requests` and wait on a private
reply queue until the host answers or the timeout expires (option
timeout(Seconds), default the flag `robot_bridge_timeout`, 30 s); the queue
and its threading model are bridge_queue.pl's. Because the host serves
requests between two learning steps, a table read or written by an agent is
a consistent snapshot.

The verbs are read and write, at every layer a Q-table passes (README,
"Words"): this module's read_table/3 and write_table/3, the host's
`read_table`/`write_table` requests, the provider's `read_table()` and
`write_table()` in Python. The names of before, get_qtable/2,3,
set_qtable/2,3, get_visits/2,3, get_qtable_and_visits/3,4, get_params/2,3
and set_params/2,3, are kept as deprecated aliases for programs written
against them.

A table is the term qtable(Shape, Values): Shape = [NStates, NActions]
(positive integers), Values the flat row-major list of NStates*NActions
floats. Between the agent thread and the host the values travel in a
compact form, selected with bridge_set_codec/1:

  - `fts`: the string produced by fast_term_serialized/2, whose bytes the
    Python side reads and writes with numpy. The host selects it only after
    a start-up self-test showed that its encoder produces exactly the bytes
    this Prolog produces (fast_term_serialized/2 crashes the process on
    malformed input, so it is never given bytes of unknown origin).
  - `text`: comma-separated float text, slower but safe (the default).

Both formats are defined, on this side, in table_codec.pl only (their
Python side is `dfrl.pybridge.codec`).

A write is validated once, by the host where it enters Python
(registered shape or layout, number of values, finite values); here one
write path (write_checked/5) serves tables and parameters and checks only
what it needs to build the request.

A robot may offer its learnable parameters instead of (a function
learner) or beside (a tabular learner that also exposes them) a Q-table:
one flat vector of floats with a layout, read with read_params/3 as
params(Layout, Samples, Values) and written with write_params/3 as
params(Layout, Values). Layout is a list Name-Dims (Name an atom, Dims a
list of integers), the vector the blocks' row-major values in order;
Samples the number of steps the learner has learnt from (the FedAvg
weight). The values travel in the same codec as tables and a write is
validated by the host the same way (registered layout, number of values,
finite values).

The bridge implements the platform's resource hook (robot_resources.pl):
an agent that calls robot_resources:read_robot_table/3,
read_robot_tables/4 or write_robot_table/3 reaches the robots registered
here.

This module loads in plain `swipl` as well; there, some thread must call
bridge_next_request/2 and bridge_reply/2 for the requests to be answered.

The bridge is four modules: this one (its public face: everything is
exported from here, the deprecated names and the resource hook),
bridge_queue.pl (the request queue and its threading model),
bridge_registry.pl (the robots and the codec) and bridge_tables.pl (the
table and parameter API).
*/

		 /*******************************
		 *      DEPRECATED NAMES        *
		 *******************************/

%   The names of before read_table/write_table became the one verb pair
%   of the Q-table's path (README, "Words"); programs written against
%   them still work.

%!  get_qtable(+Robot, -Table) is det.
%!  get_qtable(+Robot, -Table, +Options) is det.
%   Deprecated: read_table/2,3.
get_qtable(Robot, Table) :- read_table(Robot, Table, []).
get_qtable(Robot, Table, Options) :- read_table(Robot, Table, Options).

%!  set_qtable(+Robot, +Table) is det.
%!  set_qtable(+Robot, +Table, +Options) is det.
%   Deprecated: write_table/2,3.
set_qtable(Robot, Table) :- write_table(Robot, Table, []).
set_qtable(Robot, Table, Options) :- write_table(Robot, Table, Options).

%!  get_visits(+Robot, -Table) is det.
%!  get_visits(+Robot, -Table, +Options) is det.
%   Deprecated: read_visits/2,3.
get_visits(Robot, Table) :- read_visits(Robot, Table, []).
get_visits(Robot, Table, Options) :- read_visits(Robot, Table, Options).

%!  get_qtable_and_visits(+Robot, -Table, -Visits) is det.
%!  get_qtable_and_visits(+Robot, -Table, -Visits, +Options) is det.
%   Deprecated: read_table_and_visits/3,4.
get_qtable_and_visits(Robot, Table, Visits) :-
    read_table_and_visits(Robot, Table, Visits, []).
get_qtable_and_visits(Robot, Table, Visits, Options) :-
    read_table_and_visits(Robot, Table, Visits, Options).

%!  get_params(+Robot, -Params) is det.
%!  get_params(+Robot, -Params, +Options) is det.
%   Deprecated: read_params/2,3.
get_params(Robot, Params) :- read_params(Robot, Params, []).
get_params(Robot, Params, Options) :- read_params(Robot, Params, Options).

%!  set_params(+Robot, +Params) is det.
%!  set_params(+Robot, +Params, +Options) is det.
%   Deprecated: write_params/2,3.
set_params(Robot, Params) :- write_params(Robot, Params, []).
set_params(Robot, Params, Options) :- write_params(Robot, Params, Options).

		 /*******************************
		 *            SHUTDOWN          *
		 *******************************/

%!  bridge_shutdown is det.
%
%   Forget all robots, answer every waiting caller with
%   existence_error(robot, Robot) (existence_error(robot_service, host)
%   for a service request) and destroy the request queues. Called by
%   the host before it stops.

bridge_shutdown :-
    with_mutex(robot_bridge,
               ( bridge_forget_robots,
                 queue_shutdown )).

		 /*******************************
		 *     RESOURCE HOOK (C1)       *
		 *******************************/

%   The platform's resource hook, robot_resources.pl: the robots of this
%   process are its resources. robot_resources checks the arguments and the
%   robot's existence, then calls one of these; errors pass through.

:- multifile
    robot_resources:robot/2,
    robot_resources:host_read_table/3,
    robot_resources:host_read_tables/4,
    robot_resources:host_write_table/3,
    robot_resources:host_read_params/3,
    robot_resources:host_write_params/3,
    robot_resources:takes_packed_values/0.

robot_resources:robot(Robot, Props) :-
    bridge_robot(Robot, Props).
robot_resources:takes_packed_values.
robot_resources:host_read_table(Robot, Table, Options) :-
    read_table(Robot, Table, Options).
robot_resources:host_read_tables(Robot, Table, Visits, Options) :-
    read_table_and_visits(Robot, Table, Visits, Options).
robot_resources:host_write_table(Robot, Table, Options) :-
    write_table(Robot, Table, Options).
robot_resources:host_read_params(Robot, Params, Options) :-
    read_params(Robot, Params, Options).
robot_resources:host_write_params(Robot, Params, Options) :-
    write_params(Robot, Params, Options).

		 /*******************************
		 *           MESSAGES           *
		 *******************************/

:- multifile prolog:error_message//1.

prolog:error_message(python_error(Class, Message)) -->
    [ 'Python ~w: ~w'-[Class, Message] ].
