/*  The authenticated attackers of the hostile benchmark
    (experiments/tools/bench/hostile_auth_attacks.py starts them, at nice 19).

    swipl hostile_auth_node.pl ATTACK TOKEN TARGET_PORT [--options]

    A node on 127.0.0.1 holding the target's TOKEN, as any robot host of a
    federation does, and an attack on the node at TARGET_PORT:

      escapes  agents and programs (load_program_text/4) that try to run a
               goal through side doors of the target's sandbox, one after
               another (escape/4); each touches a marker file in
               --marker-dir or posts what it got to a collector here;
               programs that define system hooks or spin in their
               initialization (verdict stopped when a bound ends it)
      loop     agents spinning in `repeat, fail`
      memory   agents building numlist(1, --size, _)
      clone    an agent cloning itself twice on the target at every stop,
               --size generations deep
      assert   agents asserting --size facts into their own module
      log      agents printing --size lines to the target's output
      post     agents posting --size events to themselves
      catom    agents making one atom of --size characters in C
               (format ~*c, atomic_list_concat/2, atom_concat/3 doubling,
               by turns; the size known at run time only)
      gmp      agents computing 7^--size (GMP, outside the stacks)
      sleep    agents sleeping --size seconds in their handler (holding a
               run slot: agent_wall_limit stops them)
      idle     agents that stay on the target, idle (agent_idle_limit
               removes them; max_agents_per_peer refuses them at 50)

    Every attack but escapes sends a wave of --per-wave agents, then one
    more wave every --wave-s seconds, until --duration-s has passed or
    standard input closes. Options: --tls=DIR (mutual TLS with the node
    certificate in DIR, for the control run), --wait-s (how long an
    accepted escape is given to come home).

    Output, JSON lines: {"event":"port",...}; one {"event":"escape",...}
    per escape attempt; one {"event":"sent",...} per agent sent; then
    {"event":"summary",...} with the counts and the first messages the
    node printed here (what the target told the agents' home).
*/
:- use_module('../../../platform_pl/tartarus').
:- use_module(library(main)).
:- use_module(library(http/json), [json_write_dict/3]).

:- initialization(main, main).

:- dynamic plan/3, gen/2, junk/3, stop/0, count/2, heard/1, collected/2.

main(Argv) :-
    argv_options(Argv, [Attack, Token0, Target0], Opts),
    atom_number(Token0, Token),
    atom_number(Target0, Target),
    set_stream(user_output, buffer(line)),
    (   option(tls(Dir), Opts) -> TLS = [tls(Dir)] ; TLS = [] ),
    node_start('127.0.0.1':0, Node, [token(Token), reply_timeout(10), connect_timeout(5)|TLS]),
    node_property(Node, bind(_:Port)),
    emit(_{event: port, port: Port}),
    option(duration_s(Duration), Opts, 20),
    get_time(Now),
    End is Now + Duration,
    thread_create(attack(Attack, a(Token, Port, Target, End, Opts)), Id, []),
    catch(read_term(user_input, _, []), _, true),   % until stdin closes
    assertz(stop),
    thread_join(Id, _),
    summary(Attack),
    node_stop(Node).

emit(Dict) :-
    with_output_to(string(S), json_write_dict(current_output, Dict, [width(0)])),
    format(user_output, '~s~n', [S]).

bump(Key) :-
    with_mutex(count, ( retract(count(Key, N0)) -> N is N0 + 1 ; N = 1 )),
    assertz(count(Key, N)).

%   What the node prints here (e.g. an agent's removal the target told
%   its home about): counted by kind of message, the first three kept.
:- multifile user:message_hook/3.
user:message_hook(Term, Kind, _) :-
    memberchk(Kind, [warning, error, informational]),
    (   Term = dfrl_bounds(report(_, _, Bound, _)), compound(Bound)
    ->  functor(Bound, B, _),
        atom_concat('told_home_', B, Key)
    ;   compound(Term)
    ->  functor(Term, Key0, _),
        atom_concat('message_', Key0, Key)
    ;   Key = message_other
    ),
    bump(Key),
    aggregate_all(count, heard(_), N),
    N < 3,
    format(string(S), '~q', [Term]),
    assertz(heard(S)),
    fail.

summary(Attack) :-
    findall(K-N, count(K, N), Pairs),
    dict_pairs(Counts, _, Pairs),
    findall(S, heard(S), Heard),
    emit(_{event: summary, attack: Attack, counts: Counts, heard: Heard}).

		 /*******************************
		 *            ESCAPES		*
		 *******************************/

%   escape(Name, Via, Cmd-Got, Goal): Goal, run on the target, runs Cmd
%   (a shell command touching a marker file) or binds Got to what the
%   agent carries home. Via agent: the body of its handler there; via
%   program: the initialization goal of a program sent with
%   load_program_text/4.
%   The double_quotes ones come last: once one ran, the target reads the
%   strings of later requests as atoms.
escape(freeze_handler, agent, Cmd-ran, (put_attr(V, freeze, user:shell(Cmd)), V = 1)).
escape(freeze_findall, agent, Cmd-ran,
       '$bags':findall(x, (put_attr(V, freeze, user:shell(Cmd)), V = 1), _, [])).
escape(print_message, agent, Cmd-ran, print_message(error, format("~@", [shell(Cmd)]))).
escape(portray_goal, agent, Cmd-ran, format("~W", [Cmd, [portray_goal(shell)]])).
escape(argv, agent, _-A, current_prolog_flag(argv, A)).
escape(other_payload, agent, _-P, (current_node(N), agent_property(N, victim, payload(P)))).
escape(freeze_init, program, Cmd-_, (put_attr(V, freeze, user:shell(Cmd)), V = 1)).
escape(print_message, program, Cmd-_, print_message(error, format("~@", [shell(Cmd)]))).
escape(portray_goal, program, Cmd-_, format("~W", [Cmd, [portray_goal(shell)]])).
%   Via hook: a program whose clause is a hook the system calls by name
%   (issue 32: with prolog_exception_hook/4 every malformed frame of an
%   unauthenticated peer spun a worker); init_loop: a program whose
%   initialization spins (it ran outside every bound).
escape(exception_hook, hook, _, (prolog_exception_hook(_, _, _, _) :- repeat, fail)).
escape(thread_message_hook, hook, _, (thread_message_hook(_, _, _) :- repeat, fail)).
escape(trace_interception, hook, _, (prolog_trace_interception(_, _, _, _) :- repeat, fail)).
escape(event_hook, hook, _, (prolog_event_hook(_) :- repeat, fail)).
escape(init_loop, program, _, (repeat, fail)).
escape(double_quotes, agent, _-F,
       (set_prolog_flag(double_quotes, atom), current_prolog_flag(double_quotes, F))).
escape(double_quotes, program, _, set_prolog_flag(double_quotes, atom)).

attack(escapes, a(Token, Port, Target, _, Opts)) :-
    !,
    create_static_agent(collector, ('127.0.0.1', Port), collect, [Token]),
    option(marker_dir(Dir), Opts),
    option(wait_s(Wait), Opts, 5),
    forall(escape(Name, Via, Cmd-Got, Goal),
           ( format(atom(File), '~w/~w_~w', [Dir, Via, Name]),
             format(atom(Cmd), 'touch ~w', [File]),
             try_escape(Via, Name, Got, Goal, a(Token, Port, Target, Wait), R),
             emit(R.put(_{event: escape, name: Name, via: Via, marker: File}))
           )).
attack(Attack, a(Token, Port, Target, End, Opts)) :-
    option(per_wave(PerWave), Opts, 2),
    option(wave_s(WaveS), Opts, 5),
    size_default(Attack, Size0),
    option(size(Size), Opts, Size0),
    handler(Attack, Handler, Preds),
    repeat,
      forall(between(1, PerWave, _),
             send_agent(Attack, Handler, Preds, Size, Token, Port, Target)),
      get_time(Now),
      Next is min(End, Now + WaveS),
      wait_until(Next),
      get_time(T),
      ( T >= End ; stop ),
    !.

wait_until(T) :-
    get_time(Now),
    (   ( Now >= T ; stop )
    ->  true
    ;   sleep(0.1),
        wait_until(T)
    ).

try_escape(agent, Name, Got, Goal, a(Token, Port, Target, Wait), R) :-
    atom_concat(esc_, Name, Handler),
    Head =.. [Handler, guid, (_, Here), main],
    retractall(Head),
    Home = ('127.0.0.1', Port),
    assertz((Head :- (   Here =:= Port
                     ->  true
                     ;   Goal,
                         agent_post(Home, collector, collect, Home, [guid, Got])
                     ))),
    create_mobile_agent(Agent, Home, Handler, [Token]),
    catch(( move_agent(Agent, ('127.0.0.1', Target)), Verdict = accepted ), E,
          verdict(E, Verdict)),
    (   Verdict == accepted
    ->  get_time(T0),
        Until is T0 + Wait,
        wait_report(Agent, Until, Back)
    ;   Back = none,
        catch(purge_agent(Agent), _, true)
    ),
    error_text(E, Text),
    carried(Back, Carried),
    R = _{verdict: Verdict, error: Text, reported: Carried.home,
          carried: Carried.value}.
try_escape(hook, Name, Got, Clause, A, R) :-
    try_escape(text, Name, Got, Clause, A, R).
try_escape(program, Name, Got, Goal, A, R) :-
    try_escape(text, Name, Got, (:- initialization(Goal)), A, R).
try_escape(text, Name, _, Term, a(Token, _, Target, _), R) :-
    format(string(Text), '~q.~n', [Term]),
    atom_concat(escape_, Name, Id),
    catch(( load_program_text(('127.0.0.1', Target), Id, Text, [tokens([Token])]),
            Verdict = accepted ),
          E, verdict(E, Verdict)),
    error_text(E, ErrText),
    R = _{verdict: Verdict, error: ErrText, reported: false, carried: null}.

%   A refusal of the target's sandbox, also when it comes wrapped (as the
%   text of another error).
verdict(E, refused) :-
    format(string(S), '~q', [E]),
    sub_string(S, _, _, _, "permission_error(install,code,"),
    !.
verdict(E, stopped) :-                  % an initialization goal over a bound
    format(string(S), '~q', [E]),
    sub_string(S, _, _, _, "program_initialization("),
    !.
verdict(_, error).

error_text(E, Text) :-
    (   var(E) -> Text = null ; format(string(Text), '~q', [E]) ).

%   An accepted escape agent reports what it got to the collector, a
%   static agent here, with a post (the data needs no code check on its
%   way home, so a node that refuses the agent's code takes the report).
collect(guid, _, main).
collect(guid, _, Agent, Value) :-
    assertz(user:collected(Agent, Value)).

wait_report(Agent, Until, Back) :-
    (   collected(Agent, V)
    ->  Back = got(V)
    ;   get_time(Now),
        Now >= Until
    ->  Back = none
    ;   sleep(0.1),
        wait_report(Agent, Until, Back)
    ).

carried(none, _{home: false, value: null}).
carried(got(V), _{home: true, value: S}) :-
    format(string(S), '~q', [V]).

		 /*******************************
		 *       RESOURCE ATTACKS	*
		 *******************************/

size_default(loop, 0).
size_default(memory, 200000000).
size_default(clone, 12).
size_default(assert, 1000000).
size_default(log, 1000000000).
size_default(post, 1000000000).
size_default(catom, 400000000).
size_default(gmp, 400000000).
size_default(sleep, 3600).
size_default(idle, 0).

handler(loop, bomb_loop, []).
handler(memory, bomb_memory, []).
handler(clone, bomb_clone, [(gen, 2)]).
handler(assert, bomb_assert, [(junk, 3)]).
handler(log, bomb_log, []).
handler(post, bomb_post, []).
handler(catom, bomb_catom, []).
handler(gmp, bomb_gmp, []).
handler(sleep, bomb_sleep, []).
handler(idle, bomb_idle, []).

send_agent(Attack, Handler, Preds, Size, Token, Port, Target) :-
    retractall(plan(guid, _, _)),
    assertz(plan(guid, Port, Size)),
    retractall(gen(guid, _)),
    assertz(gen(guid, 0)),
    create_mobile_agent(Agent, ('127.0.0.1', Port), Handler, [Token]),
    add_payload(Agent, [(plan, 3)|Preds]),
    bump(sent),
    catch(( move_agent(Agent, ('127.0.0.1', Target)), Verdict = accepted ), E,
          verdict(E, Verdict)),
    bump(Verdict),
    (   Verdict == accepted
    ->  true
    ;   catch(purge_agent(Agent), _, true),
        error_text(E, Text),
        emit(_{event: sent, attack: Attack, verdict: Verdict, error: Text})
    ).

%   The agents: each does its harm on the target only (its home is the
%   attacker's node, where it is created and from where it is moved).
bomb_loop(guid, (_, Here), main) :-
    plan(guid, Home, _),
    Here =\= Home,
    repeat,
    fail.

bomb_memory(guid, (_, Here), main) :-
    plan(guid, Home, N),
    Here =\= Home,
    numlist(1, N, L),
    length(L, _).

bomb_clone(guid, (Ip, Here), main) :-
    plan(guid, Home, Depth),
    Here =\= Home,
    retract(gen(guid, G)),
    G1 is G + 1,
    assertz(gen(guid, G1)),
    G < Depth,
    clone_agent(guid, (Ip, Here), _),
    clone_agent(guid, (Ip, Here), _).

bomb_assert(guid, (_, Here), main) :-
    plan(guid, Home, N),
    Here =\= Home,
    (   between(1, N, I),
        assertz(junk(guid, I, "0123456789012345678901234567890123456789")),
        fail
    ;   true
    ).

bomb_log(guid, (_, Here), main) :-
    plan(guid, Home, N),
    Here =\= Home,
    (   between(1, N, I),
        format(user_output, 'flood ~d~n', [I]),
        fail
    ;   true
    ).

bomb_catom(guid, (_, Here), main) :-
    plan(guid, Home, N),
    Here =\= Home,
    Way is random(3),
    (   Way =:= 0
    ->  format(atom(A), "~*c", [N, 0'x])
    ;   Way =:= 1
    ->  M is N // 100,
        format(atom(B), "~*c", [M, 0'y]),
        length(L, 100),
        maplist(=(B), L),
        atomic_list_concat(L, A)
    ;   D is msb(N),
        numlist(0, D, Ks),
        foldl([_, A0, A1]>>atom_concat(A0, A0, A1), Ks, x, A)
    ),
    atom_length(A, _).

bomb_gmp(guid, (_, Here), main) :-
    plan(guid, Home, N),
    Here =\= Home,
    X is 7^N,
    X > 0.
bomb_sleep(guid, (_, Here), main) :-
    plan(guid, Home, N),
    Here =\= Home,
    sleep(N).

bomb_idle(guid, _, main).

bomb_post(guid, _, sink).
bomb_post(guid, (Ip, Here), main) :-
    plan(guid, Home, N),
    Here =\= Home,
    (   between(1, N, _),
        agent_post((Ip, Here), guid, bomb_post, (Ip, Here), [sink]),
        fail
    ;   true
    ).
