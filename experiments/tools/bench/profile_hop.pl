/*  The phases of one agent hop, timed one by one in one process.

    swipl profile_hop.pl FLOATS REPS [profile] [store]

    Makes the benchmark agent of bench_migrate.pl (a payload of FLOATS
    floats) on a node and runs, REPS times each, the work a hop does at
    either end, printing the median of each phase in ms as one JSON
    line "PHASES {...}". With `profile`, runs SWI-Prolog's profiler over
    REPS full sequences and prints its flat table. With `store`, the
    destination node has a custody store (fsync'ed files).
    The network and the threads are not in these figures: the end-to-end
    hop minus their sum is what the wire, the handshake frames and the
    thread hand-offs cost.
*/
:- use_module('../../../platform_pl/tartarus').
:- use_module('../../../platform_pl/agents').
:- use_module('../../../platform_pl/wire').
:- use_module('../../../platform_pl/custody').
:- use_module('../../../platform_pl/code_safety').
:- use_module(library(main)).
:- use_module(library(statistics)).
:- use_module(library(memfile)).

:- dynamic bench/3, data/2, departed/2, done/2, unsaid/2, plan/2.

:- initialization(main, main).

:- include(bench_hop_handler).

main(Argv) :-
    Argv = [Floats0, Reps0|Flags],
    atom_number(Floats0, Floats),
    atom_number(Reps0, Reps),
    (   memberchk(store, Flags)
    ->  tmp_file(custody, Dir), make_directory(Dir), StoreOpt = [store(Dir)]
    ;   StoreOpt = []
    ),
    node_start(localhost:0, Src, [token(1)]),
    node_start(localhost:0, Dst, [token(1)|StoreOpt]),
    custody_open(Dst, _),
    findall(F, ( between(1, Floats, I), F is I * 0.001 + 0.5 ), Data),
    assertz(data(guid, Data)),
    assertz(done(guid, 0)),
    assertz(unsaid(guid, [])),
    assertz(plan(guid, plan(1, 2, 3))),
    with_node(Src, ( create_mobile_agent(bencher, bench, [1]),
                     add_payload(bencher, [(data,2), (done,2), (unsaid,2), (plan,2), (departed,2)]) )),
    (   memberchk(profile, Flags)
    ->  profile(forall(between(1, Reps, _), sequence(Src, Dst, _)), [top(40)])
    ;   findall(T, ( between(1, Reps, _), sequence(Src, Dst, T) ), Ts),
        Ts = [T0|_],
        dict_keys(T0, Keys),
        findall(K-Med, ( member(K, Keys),
                         findall(V, ( member(D, Ts), get_dict(K, D, V) ), Vs),
                         median(Vs, Med) ), Pairs),
        dict_pairs(Out, phases, Pairs),
        with_output_to(string(S), json_write_dict(current_output, Out, [width(0)])),
        format("PHASES ~s~n", [S])
    ),
    halt(0).

:- use_module(library(http/json)).

median(Vs, M) :-
    msort(Vs, S), length(S, N), I is N // 2, nth0(I, S, M0), M is round(M0 * 1000) / 1000.

%   One hop's work, phase by phase; T is a dict Phase-Ms.
sequence(Src, Dst, T) :-
    MigId = 'src/bencher/1234/5678',
    t(export,       agent_export(Src, bencher, R0)),
    R0 = agent(N, H, K, _, P, Ps, Cs, Hs),
    Record = agent(N, H, K, [], P, Ps, Cs, Hs),
    Msg = transfer(MigId, move, localhost:1, 0.0, Record, inc),
    t(serialise,    fast_term_serialized(Msg, Bytes)),
    t(frame_write,  frame_to_memory(Msg, Mem)),
    t(frame_read,   frame_from_memory(Mem, Msg2)),
    Msg2 = transfer(_, _, _, _, Record2, _),
    t(deserialise,  fast_term_serialized(_, Bytes)),
    t(check,        check_agent_record(Record2)),
    t(seal,         record_seal(MigId, Record2, _)),
    Record2 = agent(N2, H2, K2, _, P2, Ps2, Cs2, Hs2),
    t(install,      agent_install(Dst, agent(N2, H2, K2, [1], P2, Ps2, Cs2, Hs2),
                                  staged(MigId), Name)),
    t(custody_stage, custody_stage(Dst, Name, MigId, localhost:1, inc, 0.0)),
    t(activate_store, custody_activated(Dst, Name, MigId)),
    t(remove,       agent_remove(Dst, Name)),
    t(text_write,   format(string(Text), "~k .~n", [Record])),
    t(text_read,    term_string(_, Text)),
    phases_dict(T).

:- thread_local acc/2.

t(Phase, Goal) :-
    get_time(T0),
    call(Goal), !,
    get_time(T1),
    Ms is (T1 - T0) * 1000,
    assertz(acc(Phase, Ms)).

phases_dict(T) :-
    findall(Ph-Ms, retract(acc(Ph, Ms)), Pairs),
    dict_pairs(T, phases, Pairs).

frame_to_memory(Msg, MF) :-
    new_memory_file(MF),
    setup_call_cleanup(open_memory_file(MF, write, W, [encoding(octet)]),
                       frame_write(W, binary, Msg),
                       close(W)).

frame_from_memory(MF, Msg) :-
    setup_call_cleanup(open_memory_file(MF, read, In, [encoding(octet)]),
                       frame_read(In, frame(_, Msg), [binary(true), max_size(1000000000)]),
                       close(In)),
    free_memory_file(MF).
