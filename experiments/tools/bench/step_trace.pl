:- module(step_trace,
          [ step_trace_start/0,
            step_trace_write/1          % +Role
          ]).
:- use_module(library(prolog_wrap), [wrap_predicate/4]).
:- use_module(library(http/json), [json_write_dict/3]).

/** <module> Timing the steps of hops and rounds, for the benchmarks

With the environment variable DFRL_STEP_TRACE=DIR set, step_trace_start/0
wraps the platform's predicates listed in traced/2 (those this version
of the platform has; wrap_predicate/4, nothing changed in them), so that
every call records its step, its start and end (get_time/1) and its
thread; step_trace_write(Role) writes the records to DIR/Role.jsonl, one
JSON object a line {"step", "t0", "t1", "thread"}. Without the variable
both do nothing.

`dfrl bench migrate` traces a hop with it (bench_migrate.pl; migrate.py's
phase_breakdown/2 reads the files) and `dfrl bench round --trace DIR` a
round (every robot process; round.py sums the steps up). A wrapped call
costs some 20 us, so a traced run is slower than an untraced one: its
figures compare steps with each other, they are not the hop's or the
round's time.
*/

:- dynamic step_/4.                     % Step, T0, T1, Thread

%   traced(Module:Head, Step): the steps timed, Step a term of Head's
%   arguments (bound after the call). No meta-predicate: its goal would
%   run in this module.
%   The hop: leaving, the hand-over, arriving.
traced(agent_records:agent_export(_, _, _), export).
traced(transport_pool:transport_acquire(_, _, _, _), acquire).
traced(wire:frame_write(_, _, T), write(F)) :- term_functor(T, F).
traced(wire:frame_read(_, Fr, _), read(F)) :- ( Fr = frame(_, T) -> term_functor(T, F) ; F = eof ).
traced(wire:body_bytes(_, T, _), serialise(F)) :- term_functor(T, F).
traced(code_safety:check_agent_record(_), check).
traced(code_safety:record_sealed(_, _, _), sealed).
traced(agent_records:agent_install(_, _, _, _), install).
traced(agent_records:agent_install(_, _, _, _, _), install).
traced(agent_bounds:bounds_install(_, _, _, _), bounds_install).
traced(bounds_limits:module_size(_, _), module_size).
traced(custody:custody_stage(_, _, _, _, _, _), custody_stage).
traced(custody:custody_commit(_, _, _, _, _), custody_commit).
traced(agent_execution:agent_remove(_, _), remove).
traced(migration_arrival:receive_transfer(_, _, _, _), receive_transfer).
traced(migration_arrival:activate(_, _, _), activate).
traced(agent_execution:agent_run(_, _, _, _), agent_run).
traced(tartarus:move_agent(_, _), move_agent).
traced(migration:agent_move(_, _, _), agent_move).
traced(migration:local_node_at(_, _), local_node_at).
traced(migration:begin_departure(_, _, _, _), begin_departure).
traced(node_identity:node_for_address(_, _), node_for_address).
traced(migration:prepare(_, _, _, _, _, _), prepare).
traced(migration:hand_over(_, _, _, _, _, _), hand_over).
traced(migration:send_commit(_, _, _, _, _), send_commit).
traced(transport_pool:transport_release(_), release).
traced(node_connection:serve_term(T, _, _), serve(F)) :- term_functor(T, F).
traced(agent_execution:agent_execute(_, _, _, _), agent_execute).
traced(agent_execution:run_handler(_, _, _), handler).
traced(custody:custody_activated(_, _, _), custody_activated).
traced(agent_registry:agent_record_hop(_, _, _), record_hop).
%   A stop of the dFRL agent (in a robot process): its step, the robot's
%   table through the bridge, the aggregate, the round state, the lease.
traced(dfrl_rounds:step(_, _), step).
traced(dfrl_rounds:go(_, _, _, _), go).
traced(dfrl_round_state:get_state(_, _, _), get_state).
traced(dfrl_round_state:put_state(_, _, _), put_state).
traced(dfrl_robot_io:read_robot(_, _, _, _, _), read_robot).
traced(dfrl_robot_io:write_robot(_, _, _), write_robot).
traced(bridge_queue:bridge_call(_, _, _, _, _), bridge_call).
traced(dfrl_aggregation:aggregate_fold(_, _, _, _, _), fold).
traced(dfrl_lease:lease_depart(_, _, _, _, _, _), lease_depart).
traced(dfrl_lease:lease_departed(_), lease_departed).
traced(dfrl_lease:lease_arrived(_, _, _), lease_arrived).

term_functor(T, F) :-
    (   var(T)
    ->  F = var
    ;   T = ok(R)
    ->  term_functor(R, F0),
        format(atom(F), 'ok(~w)', [F0])
    ;   compound(T)
    ->  compound_name_arity(T, F, _)
    ;   F = T
    ).

%!  step_trace_start is det.
%
%   With DFRL_STEP_TRACE set, wrap every traced predicate this process
%   has (load the platform first). Safe to call again (wrap_predicate/4
%   replaces a wrapper of the same name).

step_trace_start :-
    (   getenv('DFRL_STEP_TRACE', _)
    ->  forall(( traced(M:H, _),
                 functor(H, N, A),
                 current_predicate(M:N/A) ),     % steps of this version of the platform
               ( functor(G, N, A),
                 wrap_predicate(M:G, dfrl_trace, W, step_trace:traced_call(M:G, W)) ))
    ;   true
    ).

traced_call(MG, W) :-
    get_time(T0),
    call(W),
    get_time(T1),
    (   traced(MG, Step) -> true ; Step = unknown ),
    thread_self(Me),
    ( atom(Me) -> Th = Me ; thread_property(Me, id(Th)) ),
    assertz(step_(Step, T0, T1, Th)).

%!  step_trace_write(+Role) is det.
%
%   With DFRL_STEP_TRACE=DIR set, write the steps recorded so far to
%   DIR/Role.jsonl (replacing it) and forget them.

step_trace_write(Role) :-
    (   getenv('DFRL_STEP_TRACE', Dir)
    ->  format(atom(File), '~w/~w.jsonl', [Dir, Role]),
        setup_call_cleanup(
            open(File, write, Out),
            forall(retract(step_(Step, T0, T1, Th)),
                   ( format(atom(S), '~w', [Step]),
                     json_write_dict(Out, _{step:S, t0:T0, t1:T1, thread:Th}, [width(0)]),
                     nl(Out) )),
            close(Out))
    ;   true
    ).
