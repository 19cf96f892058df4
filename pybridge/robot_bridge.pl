:- module(robot_bridge,
          [ bridge_register_robot/2,    % +Robot, +Props
            bridge_unregister_robot/1,  % +Robot
            bridge_robot/2,             % ?Robot, ?Props
            get_qtable/2,               % +Robot, -Table
            get_qtable/3,               % +Robot, -Table, +Options
            set_qtable/2,               % +Robot, +Table
            set_qtable/3,               % +Robot, +Table, +Options
            get_visits/2,               % +Robot, -Table
            get_visits/3,               % +Robot, -Table, +Options
            get_qtable_and_visits/3,    % +Robot, -Table, -Visits
            get_qtable_and_visits/4,    % +Robot, -Table, -Visits, +Options
            get_params/2,               % +Robot, -Params
            get_params/3,               % +Robot, -Params, +Options
            set_params/2,               % +Robot, +Params
            set_params/3,               % +Robot, +Params, +Options
            bridge_next_request/2,      % -Request, +TimeoutSeconds
            bridge_service_call/3,      % +Op, -Reply, +Options
            bridge_next_service_request/2, % -Request, +TimeoutSeconds
            bridge_reply/2,             % +Id, +Reply
            bridge_set_codec/1,         % +Codec
            bridge_codec/1,             % -Codec
            bridge_attach_server/0,
            bridge_detach_server/0,
            bridge_shutdown/0,
            bridge_stop_threads/2,      % +Timeout, -Remaining
            bridge_stop_threads/3       % +Timeout, -Remaining, -Aborted
          ]).
:- use_module(table_codec,
              [ encode_values/3, decode_values/2, fts_encoded/2, float_list/2 ]).
:- use_module('../platform_pl/robot_resources', []).
:- use_module('../platform_pl/float_vectors',
              [ packed_vector/1, vector_length/2, vector_floats/2 ]).
:- autoload(library(error),
            [ must_be/2, domain_error/2, existence_error/2, type_error/2,
              instantiation_error/1 ]).
:- autoload(library(option), [option/3]).
:- autoload(library(lists), [member/2, append/3]).
:- autoload(library(apply), [include/3, foldl/4, maplist/2]).
:- autoload(library(debug), [debug/3]).

/** <module> Robot tables and parameters for agents, served by the Python host between control steps

A robot process is one Python process that embeds SWI-Prolog. Its control loop
registers each robot with bridge_register_robot/2 and, once per control
step, serves the requests that agents have queued (bridge_next_request/2 and
bridge_reply/2, called from the Python main thread by `pybridge`).

Agents, running in their own Prolog threads, call get_qtable/2,
set_qtable/2 and get_visits/2. These never call Python: they post a request
on the message queue `robot_bridge_requests` and wait on a private reply
queue until the host answers or the timeout expires (option timeout(Seconds),
default the flag `robot_bridge_timeout`, 30 s). Because the host serves
requests between two learning steps, a table read or written by an agent is
a consistent snapshot.

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

A table write is validated once, by the host where it enters Python
(registered shape, number of values, finite values); here set_qtable/3
checks only what it needs to build the request.

A robot may offer its learnable parameters instead of (a function
learner) or beside (a tabular learner that also exposes them) a Q-table:
one flat vector of floats with a layout, read with get_params/3 as
params(Layout, Samples, Values) and written with set_params/3 as
params(Layout, Values). Layout is a list Name-Dims (Name an atom, Dims a
list of integers), the vector the blocks' row-major values in order;
Samples the number of steps the learner has learnt from (the FedAvg
weight). The values travel in the same codec as tables and a write is
validated by the host the same way (registered layout, number of values,
finite values).

The bridge implements the platform's resource hook (robot_resources.pl):
an agent that calls get_robot_table/3, get_robot_tables/4 or
set_robot_table/3 reaches the robots registered here.

This module loads in plain `swipl` as well; there, some thread must call
bridge_next_request/2 and bridge_reply/2 for the requests to be answered.
*/

:- dynamic
    robot_/2,                   % Robot, Props
    pending_/3,                 % Id, ReplyQueue, Who (robot(R) or service)
    codec_/1,                   % fts | text
    server_/1,                  % ThreadId of the serving thread
    stopping_threads_/0.        % bridge_stop_threads/2 has aborted threads

:- create_prolog_flag(robot_bridge_timeout, 30.0, [type(float), keep(true)]).
:- create_prolog_flag(robot_service_timeout, 20.0, [type(float), keep(true)]).

codec_(text).

request_queue(robot_bridge_requests).
service_queue(robot_bridge_service).

%!  bridge_register_robot(+Robot, +Props) is det.
%
%   Register a robot hosted by this process, replacing an earlier
%   registration of the same robot. Robot is an atom or an integer. Props
%   is a list that says what the robot offers: shape([NStates, NActions])
%   for a Q-table, layout(Layout) for a parameter vector (at least one of
%   them), and usually algorithm(Name) and learner(tabular|function), e.g.
%   `[algorithm(qlearning), shape([64, 4]), learner(tabular)]` or
%   `[algorithm(dqn), learner(function), layout([w1-[4,16], b1-[16]])]`.
%
%   @error type_error(list, Props)
%   @error domain_error(robot_props, Props) without shape/1 or layout/1.
%   @error domain_error(shape([nstates, nactions]), Shape) for a bad shape.
%   @error domain_error(param_layout, Layout) for a bad layout.

bridge_register_robot(Robot, Props) :-
    must_be(atomic, Robot),
    must_be(list, Props),
    (   memberchk(shape(Shape), Props)
    ->  check_shape(Shape)
    ;   memberchk(layout(_), Props)
    ->  true
    ;   domain_error(robot_props, Props)
    ),
    (   memberchk(layout(Layout), Props)
    ->  layout_size(Layout, _)
    ;   true
    ),
    ensure_request_queue,
    with_mutex(robot_bridge,
               ( retractall(robot_(Robot, _)),
                 assertz(robot_(Robot, Props)) )),
    debug(robot_bridge, 'registered robot ~q ~q', [Robot, Props]).

%!  bridge_unregister_robot(+Robot) is det.
%
%   Forget Robot. Requests already queued for it are answered with
%   existence_error(robot, Robot) when the host serves them. Succeeds
%   silently if Robot was not registered.

bridge_unregister_robot(Robot) :-
    must_be(atomic, Robot),
    with_mutex(robot_bridge, retractall(robot_(Robot, _))).

%!  bridge_robot(?Robot, ?Props) is nondet.
%
%   True when Robot is registered in this process with Props.

bridge_robot(Robot, Props) :-
    robot_(Robot, Props).

%!  get_qtable(+Robot, -Table) is det.
%!  get_qtable(+Robot, -Table, +Options) is det.
%
%   Table is qtable(Shape, Values), a snapshot of Robot's Q-table taken by
%   the host between two learning steps. Options: timeout(Seconds).
%
%   @error existence_error(robot, Robot) if Robot is not registered here.
%   @error timeout_error(bridge, Robot) if the host did not answer in time.
%   @error python_error(Class, Message) if serving failed in Python.

get_qtable(Robot, Table) :-
    get_qtable(Robot, Table, []).

get_qtable(Robot, Table, Options) :-
    table_request(get_qtable(Robot), get_qtable/2, Options, Table).

%!  get_visits(+Robot, -Table) is det.
%!  get_visits(+Robot, -Table, +Options) is det.
%
%   As get_qtable/3 for the visit counts of Robot: Table is
%   qtable(Shape, Values) with the counts as floats.

get_visits(Robot, Table) :-
    get_visits(Robot, Table, []).

get_visits(Robot, Table, Options) :-
    table_request(get_visits(Robot), get_visits/2, Options, Table).

%!  get_qtable_and_visits(+Robot, -Table, -Visits) is det.
%!  get_qtable_and_visits(+Robot, -Table, -Visits, +Options) is det.
%
%   Table and Visits (as get_qtable/3 and get_visits/3) taken in the same
%   pause between two learning steps, so that they belong together (e.g.
%   for visit-weighted aggregation).

get_qtable_and_visits(Robot, Table, Visits) :-
    get_qtable_and_visits(Robot, Table, Visits, []).

get_qtable_and_visits(Robot, Table, Visits, Options) :-
    PI = get_qtable_and_visits/3,
    must_be(atomic, Robot),
    must_be(list, Options),
    registered(Robot),
    offers_table(Robot),
    bridge_call(Robot, get_qtable_and_visits(Robot), PI, Options, Reply),
    (   Reply = tables(table(QShape, QData), table(VShape, VData))
    ->  decode_table(QShape, QData, Options, Table),
        decode_table(VShape, VData, Options, Visits)
    ;   reply_error(Reply, PI)
    ).

table_request(Op, PI, Options, Table) :-
    arg(1, Op, Robot),
    must_be(atomic, Robot),
    must_be(list, Options),
    registered(Robot),
    offers_table(Robot),
    bridge_call(Robot, Op, PI, Options, Reply),
    (   Reply = table(Shape, Data)
    ->  decode_table(Shape, Data, Options, Table)
    ;   reply_error(Reply, PI)
    ).

decode_table(Shape, Data, Options, qtable(Shape, Values)) :-
    read_values(Data, Options, Values),
    check_size(Shape, Values).

%   With the option values(packed), fts data stay packed (checked whole
%   by the caller's vector_length/2, float_vectors.pl), else they are
%   decoded into a list.
read_values(Data, Options, Values) :-
    (   memberchk(values(packed), Options),
        packed_vector(Data)
    ->  Values = Data
    ;   decode_values(Data, Values)
    ).

check_size(Shape, Values) :-
    check_shape(Shape),
    Shape = [NS, NA],
    N is NS*NA,
    vector_length(Values, Len),
    (   Len =:= N
    ->  true
    ;   domain_error(qtable_size(N), Len)
    ).

%!  set_qtable(+Robot, +Table) is det.
%!  set_qtable(+Robot, +Table, +Options) is det.
%
%   Replace Robot's Q-table with Table = qtable(Shape, Values). Shape must
%   be the registered shape and Values NStates*NActions finite numbers
%   (integers are converted to floats); the host checks that where the
%   table enters Python. If anything is wrong the robot's table is left
%   unchanged. Options: timeout(Seconds); every other option Name(Value)
%   with an atomic Value (e.g. round(3), agent(dfrl_q), epoch(1)) is
%   handed to the host with the write, which records where it came from.
%
%   @error existence_error(robot, Robot) if Robot is not registered here.
%   @error type_error(qtable, Table) if Table is not qtable(Shape, Values).
%   @error type_error(number, X) for a non-number in Values.
%   @error domain_error(shape(Registered), Shape) on a shape mismatch.
%   @error domain_error(qtable_size(N), Len) if Values has Len elements.
%   @error domain_error(finite_float, X) for an infinite or NaN value.
%   @error timeout_error(bridge, Robot) if the host did not answer in time.

set_qtable(Robot, Table) :-
    set_qtable(Robot, Table, []).

set_qtable(Robot, Table, Options) :-
    must_be(atomic, Robot),
    must_be(list, Options),
    registered(Robot),
    offers_table(Robot),
    (   var(Table)
    ->  instantiation_error(Table)
    ;   Table = qtable(Shape, Values0)
    ->  true
    ;   type_error(qtable, Table)
    ),
    must_be(ground, Shape),
    must_be_values(Values0),
    write_values(Robot, set_qtable(Robot, Shape), Values0, set_qtable/2, Options).

must_be_values(Values) :-
    (   packed_vector(Values)
    ->  true
    ;   must_be(list, Values)
    ).

%   write_values(+Robot, +Op0, +Values0, +PI, +Options)
%
%   Send the write Op0 extended with the encoded Values0 and the write's
%   origin (set_qtable(Robot, Shape, Data, Origin) or set_params(Robot,
%   Layout, Data, Origin)); throw the host's error. With fts the values are
%   first sent as they are (see fts_encoded/2): a type_error(float_list, _)
%   answer makes it convert them and ask again.

write_values(Robot, Op0, Values, PI, Options) :-
    packed_vector(Values),
    !,
    (   bridge_codec(fts)
    ->  vector_length(Values, _),       % checked whole before it is sent
        write_request(Robot, Op0, Values, PI, Options, Reply),
        (   Reply == ok
        ->  true
        ;   reply_error(Reply, PI)
        )
    ;   vector_floats(Values, List),
        write_values(Robot, Op0, List, PI, Options)
    ).
write_values(Robot, Op0, Values0, PI, Options) :-
    (   bridge_codec(fts),
        fts_encoded(Values0, Data0)
    ->  write_request(Robot, Op0, Data0, PI, Options, Reply0),
        (   Reply0 = error(type_error(float_list, _))
        ->  write_request_floats(Robot, Op0, Values0, PI, Options, Reply)
        ;   Reply = Reply0
        )
    ;   write_request_floats(Robot, Op0, Values0, PI, Options, Reply)
    ),
    (   Reply == ok
    ->  true
    ;   reply_error(Reply, PI)
    ).

write_request_floats(Robot, Op0, Values0, PI, Options, Reply) :-
    float_list(Values0, Values),
    bridge_codec(Codec),
    encode_values(Codec, Values, Data),
    write_request(Robot, Op0, Data, PI, Options, Reply).

write_request(Robot, Op0, Data, PI, Options, Reply) :-
    write_origin(Options, Origin),
    Op0 =.. [Name|Args0],
    append(Args0, [Data, Origin], Args),
    Op =.. [Name|Args],
    bridge_call(Robot, Op, PI, Options, Reply).

%!  get_params(+Robot, -Params) is det.
%!  get_params(+Robot, -Params, +Options) is det.
%
%   Params is params(Layout, Samples, Values): a snapshot of Robot's
%   learnable parameters taken by the host between two learning steps,
%   Values a flat list of floats in the order of Layout (Name-Dims
%   blocks, each row-major) and Samples the number of steps the learner
%   has learnt from (an integer >= 0, the FedAvg weight). Options:
%   timeout(Seconds).
%
%   @error existence_error(robot, Robot) if Robot is not registered here.
%   @error existence_error(params, Robot) if Robot offers no parameters.
%   @error timeout_error(bridge, Robot) if the host did not answer in time.
%   @error python_error(Class, Message) if serving failed in Python.

get_params(Robot, Params) :-
    get_params(Robot, Params, []).

get_params(Robot, Params, Options) :-
    PI = get_params/2,
    must_be(atomic, Robot),
    must_be(list, Options),
    registered(Robot),
    offers_params(Robot, _),
    bridge_call(Robot, get_params(Robot), PI, Options, Reply),
    (   Reply = params(Layout, Samples, Data)
    ->  read_values(Data, Options, Values),
        layout_size(Layout, N),
        vector_length(Values, Len),
        (   Len =:= N
        ->  Params = params(Layout, Samples, Values)
        ;   domain_error(params_size(N), Len)
        )
    ;   reply_error(Reply, PI)
    ).

%!  set_params(+Robot, +Params) is det.
%!  set_params(+Robot, +Params, +Options) is det.
%
%   Replace Robot's parameters with Params = params(Layout, Values).
%   Layout must be the registered layout and Values as many finite
%   numbers as it holds (integers are converted to floats); the host
%   checks that where the vector enters Python. If anything is wrong the
%   robot's parameters are left unchanged. Options as set_qtable/3:
%   timeout(Seconds), and the write's origin (round(N), agent(A), ...).
%
%   @error existence_error(robot, Robot) if Robot is not registered here.
%   @error existence_error(params, Robot) if Robot offers no parameters.
%   @error type_error(params, Params) if Params is not params(Layout, Values).
%   @error type_error(number, X) for a non-number in Values.
%   @error domain_error(param_layout(Registered), Layout) on a layout mismatch.
%   @error domain_error(params_size(N), Len) if Values has Len elements.
%   @error domain_error(finite_float, X) for an infinite or NaN value.
%   @error timeout_error(bridge, Robot) if the host did not answer in time.

set_params(Robot, Params) :-
    set_params(Robot, Params, []).

set_params(Robot, Params, Options) :-
    must_be(atomic, Robot),
    must_be(list, Options),
    registered(Robot),
    offers_params(Robot, _),
    (   var(Params)
    ->  instantiation_error(Params)
    ;   Params = params(Layout, Values0)
    ->  true
    ;   type_error(params, Params)
    ),
    must_be(ground, Layout),
    must_be_values(Values0),
    write_values(Robot, set_params(Robot, Layout), Values0, set_params/2, Options).

%   layout_size(+Layout, -N): N floats in a vector of Layout.
layout_size(Layout, N) :-
    (   is_list(Layout),
        Layout \== [],
        maplist(layout_block, Layout),
        foldl(add_block, Layout, 0, N),
        N > 0
    ->  true
    ;   domain_error(param_layout, Layout)
    ).

layout_block(Name-Dims) :-
    atom(Name),
    is_list(Dims),
    forall(member(D, Dims), ( integer(D), D >= 0 )).

add_block(_-Dims, N0, N) :-
    foldl(mul_dim, Dims, 1, P),
    N is N0 + P.

mul_dim(D, P0, P) :-
    P is P0*D.

offers_table(Robot) :-
    (   robot_(Robot, Props),
        memberchk(shape(_), Props)
    ->  true
    ;   throw(error(existence_error(qtable, Robot),
                    context(_, 'the robot offers parameters, no Q-table (a function learner)')))
    ).

offers_params(Robot, Layout) :-
    (   robot_(Robot, Props),
        memberchk(layout(Layout), Props)
    ->  true
    ;   throw(error(existence_error(params, Robot),
                    context(_, 'the robot offers a Q-table, no parameter vector')))
    ).

%   write_origin(+Options, -Origin): the options of a table write that say
%   where it comes from (contract K4: round(N), agent(Name), epoch(E), ...):
%   every Name(Value) option with an atomic Value except timeout/1. The
%   host records them with the write.

write_origin(Options, Origin) :-
    include(origin_option, Options, Origin).

origin_option(Option) :-
    compound(Option),
    compound_name_arity(Option, Name, 1),
    Name \== timeout,
    arg(1, Option, Value),
    atomic(Value).

check_timeout(Timeout) :-
    must_be(number, Timeout),
    (   Timeout >= 0
    ->  true
    ;   domain_error(nonneg_number, Timeout)
    ).

check_shape(Shape) :-
    (   Shape = [NS, NA],
        integer(NS), NS > 0,
        integer(NA), NA > 0
    ->  true
    ;   domain_error(shape([nstates, nactions]), Shape)
    ).

registered(Robot) :-
    (   robot_(Robot, _)
    ->  true
    ;   existence_error(robot, Robot)
    ).

reply_error(error(Formal), PI) :-
    !,
    throw(error(Formal, context(PI, _))).
reply_error(Reply, PI) :-
    throw(error(domain_error(bridge_reply, Reply), context(PI, _))).

		 /*******************************
		 *      REQUEST / REPLY         *
		 *******************************/

%!  bridge_call(+Robot, +Op, +PI, +Options, -Reply) is det.
%
%   Post request(Id, Deadline, Op) on the table request queue and wait for
%   reply(Id, Reply) on a private queue that exists only during the call.

bridge_call(Robot, Op, PI, Options, Reply) :-
    request_queue(RQ),
    host_call(RQ, robot(Robot), Op, PI, Options, Reply).

%!  bridge_service_call(+Op, -Reply, +Options) is det.
%
%   As a table request, but for the host's own service (the robot
%   process's `dfrl_robot(...)` requests, robot_service.pl): Op is posted
%   on a queue of its own, which the host serves in every state (also
%   while a sync robot serves no table request) with
%   bridge_next_service_request/2. Reply is what the host answered.
%   Options: timeout(Seconds), default the flag `robot_service_timeout`
%   (20 s).
%
%   @error existence_error(robot_service, host) if no host serves.
%   @error timeout_error(robot_service, host) if it did not answer in time.

bridge_service_call(Op, Reply, Options) :-
    must_be(nonvar, Op),
    must_be(list, Options),
    current_prolog_flag(robot_service_timeout, Default),
    option(timeout(Timeout), Options, Default),
    service_queue(SQ),
    host_call(SQ, service, Op, bridge_service_call/3, [timeout(Timeout)], Reply).

host_call(Queue, Who, Op, PI, Options, Reply) :-
    current_prolog_flag(robot_bridge_timeout, Default),
    option(timeout(Timeout), Options, Default),
    check_timeout(Timeout),
    thread_self(Me),
    (   server_(Me)
    ->  throw(error(permission_error(wait, bridge_reply, Me),
                    context(PI, 'the thread that serves bridge requests cannot wait for them')))
    ;   true
    ),
    flag(robot_bridge_request_id, Id0, Id0+1),
    Id is Id0 + 1,
    get_time(Now),
    Deadline is Now + Timeout,
    setup_call_cleanup(
        ( message_queue_create(Q),
          assertz(pending_(Id, Q, Who))
        ),
        ( catch(thread_send_message(Queue, request(Id, Deadline, Op)),
                error(existence_error(message_queue, _), _),
                ( gone_formal(Who, Gone), throw(error(Gone, context(PI, _))) )),
          (   thread_get_message(Q, reply(Id, Reply0), [timeout(Timeout)])
          ->  Reply = Reply0
          ;   format(atom(Msg), 'no reply within ~w s', [Timeout]),
              timeout_formal(Who, Formal),
              throw(error(Formal, context(PI, Msg)))
          )
        ),
        ( retractall(pending_(Id, _, _)),
          message_queue_destroy(Q)
        )).

gone_formal(robot(Robot), existence_error(robot, Robot)).
gone_formal(service, existence_error(robot_service, host)).

timeout_formal(robot(Robot), timeout_error(bridge, Robot)).
timeout_formal(service, timeout_error(robot_service, host)).

%!  bridge_next_request(-Request, +Timeout) is semidet.
%
%   Take the next request for the host, waiting at most Timeout seconds (0
%   polls). Request is request(Id, Op) with Op one of
%
%     - get_qtable(Robot)
%     - get_visits(Robot)
%     - get_qtable_and_visits(Robot)
%     - set_qtable(Robot, Shape, Data, Origin)  where Data is fts(String)
%       or text(String) (see bridge_set_codec/1) and Origin the list of
%       the write's origin options (round(N), agent(A), epoch(E), ...;
%       see set_qtable/3)
%     - get_params(Robot)
%     - set_params(Robot, Layout, Data, Origin)  Data and Origin as for
%       set_qtable
%
%   Requests whose caller has already given up are dropped. Fails if no
%   request arrived in time. Answer every request with bridge_reply/2.

bridge_next_request(Request, Timeout) :-
    request_queue(RQ),
    next_from(RQ, Request, Timeout).

%!  bridge_next_service_request(-Request, +Timeout) is semidet.
%
%   As bridge_next_request/2 for the host's service queue (see
%   bridge_service_call/3): Request is request(Id, Op), answered with
%   bridge_reply/2.

bridge_next_service_request(Request, Timeout) :-
    service_queue(SQ),
    next_from(SQ, Request, Timeout).

next_from(Queue, Request, Timeout) :-
    check_timeout(Timeout),
    get_time(Now),
    Until is Now + Timeout,
    catch(next_request(Queue, Until, Request),
          error(existence_error(message_queue, _), _),
          fail).

next_request(RQ, Until, Request) :-
    get_time(Now),
    Wait is max(0, Until - Now),
    thread_get_message(RQ, request(Id, Deadline, Op), [timeout(Wait)]),
    (   pending_(Id, _, _),
        get_time(T),
        T =< Deadline
    ->  Request = request(Id, Op)
    ;   debug(robot_bridge, 'dropped expired request ~q', [Id]),
        next_request(RQ, Until, Request)
    ).

%!  bridge_reply(+Id, +Reply) is det.
%
%   Answer request Id. Reply is one of
%
%     - table(Shape, Data)  for get_qtable/get_visits, Data as in
%       bridge_next_request/2 (an fts string must come from pybridge's
%       encoder, see bridge_set_codec/1)
%     - tables(table(Shape, QData), table(Shape, VData)) for
%       get_qtable_and_visits
%     - params(Layout, Samples, Data)  for get_params
%     - ok                  for set_qtable and set_params
%     - error(Formal)       the caller throws error(Formal, Context)
%
%   A reply to a caller that has timed out is dropped silently.

bridge_reply(Id, Reply) :-
    must_be(integer, Id),
    must_be(nonvar, Reply),
    (   retract(pending_(Id, Q, _))
    ->  catch(thread_send_message(Q, reply(Id, Reply)),
              error(existence_error(message_queue, _), _),
              true)
    ;   debug(robot_bridge, 'late reply to ~q dropped', [Id])
    ).

%!  bridge_attach_server is det.
%
%   Declare the calling thread the one that serves requests (the Python
%   main thread). get_qtable/2 and friends called from that thread throw a
%   permission error instead of waiting forever for themselves.

bridge_attach_server :-
    thread_self(Me),
    retractall(stopping_threads_),
    ensure_request_queue,
    with_mutex(robot_bridge,
               ( retractall(server_(_)),
                 assertz(server_(Me)) )).

%!  bridge_detach_server is det.
%
%   Undo bridge_attach_server/0.

bridge_detach_server :-
    retractall(server_(_)).

%!  bridge_shutdown is det.
%
%   Forget all robots, answer every waiting caller with
%   existence_error(robot, Robot) (existence_error(robot_service, host)
%   for a service request) and destroy the request queues. Called by
%   the host before it stops.

bridge_shutdown :-
    with_mutex(robot_bridge,
               ( retractall(robot_(_, _)),
                 retractall(server_(_)),
                 forall(retract(pending_(Id, Q, Who)),
                        ( gone_formal(Who, Gone),
                          catch(thread_send_message(Q, reply(Id, error(Gone))),
                                _, true) )),
                 forall(( host_queue(HQ), is_message_queue(HQ) ),
                        message_queue_destroy(HQ)) )).

%!  bridge_stop_threads(+Timeout, -Remaining) is det.
%!  bridge_stop_threads(+Timeout, -Remaining, -Aborted) is det.
%
%   Abort every Prolog thread except the caller (and the system's `gc`
%   thread), wait at most Timeout seconds for them to stop and join those
%   that are joinable. A detached thread is never joined: in SWI-Prolog
%   9.0.4 thread_join/2 on a detached thread that is exiting can deadlock
%   the process (seen here, 1 in 50 closes under load; the loop in
%   tests/pybridge/stop_detached_script.pl hangs on such a join). A
%   detached thread frees itself; it is waited for like the others.
%   Remaining lists the threads still running (e.g. blocked in a system
%   call that a signal cannot interrupt because the host runs Prolog
%   without signal handling; the platform must stop those itself). Used by the host
%   before the interpreter exits, since live threads make the embedding's
%   cleanup unsafe. Aborted is the number of threads that were running.

bridge_stop_threads(Timeout, Remaining) :-
    bridge_stop_threads(Timeout, Remaining, _).

bridge_stop_threads(Timeout, Remaining, Aborted) :-
    check_timeout(Timeout),
    (   stopping_threads_
    ->  true
    ;   assertz(stopping_threads_)
    ),
    thread_self(Me),
    findall(T, other_thread(Me, T), Threads),
    include(running_thread, Threads, Running),
    length(Running, Aborted),
    forall(member(T, Running),
           catch(thread_signal(T, abort), _, true)),
    get_time(Now),
    Deadline is Now + Timeout,
    wait_stopped(Threads, Deadline),
    include(running_thread, Threads, Remaining),
    forall(( member(T, Threads),
             \+ memberchk(T, Remaining),
             \+ catch(thread_property(T, detached(true)), _, true)
           ),
           catch(thread_join(T, _), _, true)).

other_thread(Me, T) :-
    thread_property(T, status(_)),
    T \== Me,
    \+ thread_property(T, alias(gc)).

running_thread(T) :-
    catch(thread_property(T, status(running)), _, fail).

wait_stopped(Threads, Deadline) :-
    (   \+ ( member(T, Threads), running_thread(T) )
    ->  true
    ;   get_time(Now),
        Now >= Deadline
    ->  true
    ;   sleep(0.01),
        wait_stopped(Threads, Deadline)
    ).

ensure_request_queue :-
    with_mutex(robot_bridge,
               forall(host_queue(Q),
                      (   is_message_queue(Q)
                      ->  true
                      ;   message_queue_create(_, [alias(Q)])
                      ))).

host_queue(Q) :- request_queue(Q).
host_queue(Q) :- service_queue(Q).

is_message_queue(Q) :-
    catch(message_queue_property(Q, size(_)), _, fail).

		 /*******************************
		 *            CODEC             *
		 *******************************/

%!  bridge_set_codec(+Codec) is det.
%
%   Select how values travel between agents and the host: `fts`
%   (fast_term_serialized/2 bytes) or `text`. The host sets `fts` only
%   after its start-up self-test passed.

bridge_set_codec(Codec) :-
    must_be(oneof([fts, text]), Codec),
    with_mutex(robot_bridge,
               ( retractall(codec_(_)),
                 assertz(codec_(Codec)) )).

%!  bridge_codec(-Codec) is det.
%
%   Codec is the value codec in use (`fts` or `text`).

bridge_codec(Codec) :-
    codec_(Codec), !.

		 /*******************************
		 *     RESOURCE HOOK (C1)       *
		 *******************************/

%   The platform's resource hook, robot_resources.pl: the robots of this
%   process are its resources. robot_resources checks the arguments and the
%   robot's existence, then calls one of these; errors pass through.

:- multifile
    robot_resources:robot/2,
    robot_resources:table_get/3,
    robot_resources:tables_get/4,
    robot_resources:table_set/3,
    robot_resources:params_get/3,
    robot_resources:params_set/3,
    robot_resources:takes_packed_values/0.

robot_resources:robot(Robot, Props) :-
    bridge_robot(Robot, Props).
robot_resources:takes_packed_values.
robot_resources:table_get(Robot, Table, Options) :-
    get_qtable(Robot, Table, Options).
robot_resources:tables_get(Robot, Table, Visits, Options) :-
    get_qtable_and_visits(Robot, Table, Visits, Options).
robot_resources:table_set(Robot, Table, Options) :-
    set_qtable(Robot, Table, Options).
robot_resources:params_get(Robot, Params, Options) :-
    get_params(Robot, Params, Options).
robot_resources:params_set(Robot, Params, Options) :-
    set_params(Robot, Params, Options).

		 /*******************************
		 *           MESSAGES           *
		 *******************************/

:- multifile prolog:error_message//1, user:message_hook/3.

%   Threads aborted by bridge_stop_threads/2 (e.g. idle pool workers) would
%   each print "Thread running ... died on exception: Execution Aborted".
%   That is the expected end of them, so it is not printed.

user:message_hook(abnormal_thread_completion(_, exception(E)), warning, _) :-
    stopping_threads_,
    aborted(E).

aborted('$aborted').
aborted(unwind(abort)).

prolog:error_message(timeout_error(bridge, Robot)) -->
    [ 'No reply from the robot host for robot ~q (is its control loop serving requests?)'-[Robot] ].
prolog:error_message(timeout_error(robot_service, host)) -->
    [ 'No reply from the robot process (is its main thread serving requests?)' ].
prolog:error_message(existence_error(robot_service, host)) -->
    [ 'This process serves no robot service requests' ].
prolog:error_message(python_error(Class, Message)) -->
    [ 'Python ~w: ~w'-[Class, Message] ].
