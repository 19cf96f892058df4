/*  plunit tests of codeload.pl: programs a peer sends, on a real node over
    a real connection (one process; tests/security/test_program_hooks.py
    does it across processes).
      - a syntax error is refused as a whole and the error names the
        program, line and column (issue 20);
      - every hook the Prolog system or a library calls by name is refused
        in a program, naming the hook (issue 32), with a control;
      - each program loads into a module of its own: two programs define
        the same name without clashing, and neither reaches `user`;
      - initialization goals run after the load under the agent bounds: a
        loop is stopped (CPU, wall clock), the program is unloaded and the
        node still serves.
    Run: swipl -g run_tests -t halt test_codeload.pl
*/
:- use_module('../../platform_pl/tartarus').
:- use_module('../../platform_pl/codeload').
:- use_module('../../platform_pl/code_safety', [check_program_text/2]).
:- use_module('../../platform_pl/dfrl_agent/dfrl_aggregation', []).
:- use_module(library(plunit)).
:- use_module(library(filesex), [directory_member/3, directory_file_path/3]).
:- use_module(library(readutil), [read_file_to_string/3]).

%   The node's warning about each program it stopped is expected here.
:- multifile user:message_hook/3.
user:message_hook(error(resource_error(program_initialization(_, _)), _), warning, _).

stop_all(Nodes) :- forall(member(N, Nodes), catch(node_stop(N), _, true)).

write_program(Name, Lines, Path) :-
    tmp_file(codeload, Dir),
    make_directory(Dir),
    directory_file_path(Dir, Name, Path),
    setup_call_cleanup(open(Path, write, Out),
                       forall(member(L, Lines), format(Out, "~w~n", [L])),
                       close(Out)).

node(N, A, Options) :-
    node_start('127.0.0.1':0, N, [default(false), token(7)|Options]),
    node_property(N, address(A)).

send(A, Id, Text, E) :-
    catch(( load_program_text(A, Id, Text, [tokens([7])]), E = ok ), E, true).

%   The hooks of the issue, each as a clause a program defines, with the
%   name the refusal must carry.
hook_program("prolog_exception_hook(_, _, _, _) :- repeat, fail.", prolog_exception_hook/4).
hook_program("user:prolog_exception_hook(_, _, _, _) :- repeat, fail.", prolog_exception_hook/4).
hook_program("exception(undefined_predicate, _, retry) :- repeat, fail.", exception/3).
hook_program("message_hook(_, _, _) :- repeat, fail.", message_hook/3).
hook_program("thread_message_hook(_, _, _) :- repeat, fail.", thread_message_hook/3).
hook_program("portray(_) :- repeat, fail.", portray/1).
hook_program("prolog_load_file(_, _) :- repeat, fail.", prolog_load_file/2).
hook_program("term_expansion(_, _) :- repeat, fail.", term_expansion/2).
hook_program("term_expansion(_, _, _, _) :- repeat, fail.", term_expansion/4).
hook_program("goal_expansion(_, _) :- repeat, fail.", goal_expansion/2).
hook_program("goal_expansion(_, _, _, _) :- repeat, fail.", goal_expansion/4).
hook_program("prolog_trace_interception(_, _, _, continue) :- repeat, fail.",
             prolog_trace_interception/4).
hook_program("prolog_event_hook(_) :- repeat, fail.", prolog_event_hook/1).
hook_program("portray_attvar(_) :- repeat, fail.", portray_attvar/1).
hook_program("prolog_predicate_name(_, _) :- repeat, fail.", prolog_predicate_name/2).
hook_program("prolog_clause_name(_, _) :- repeat, fail.", prolog_clause_name/2).
hook_program("prolog_list_goal(_) :- repeat, fail.", prolog_list_goal/1).
hook_program("message_property(_, _) :- repeat, fail.", message_property/2).
hook_program("resource(_, _, _) :- repeat, fail.", resource/3).
hook_program("file_search_path(_, _) :- repeat, fail.", file_search_path/2).
hook_program("library_directory(_) :- repeat, fail.", library_directory/1).
hook_program("expand_query(_, _, _, _) :- repeat, fail.", expand_query/4).
hook_program("expand_answer(_, _) :- repeat, fail.", expand_answer/2).
hook_program("prolog_file_type(_, _) :- repeat, fail.", prolog_file_type/2).
hook_program("attr_portray_hook(_, _) :- repeat, fail.", attr_portray_hook/2).
hook_program("attr_unify_hook(_, _) :- repeat, fail.", attr_unify_hook/2).
hook_program("attribute_goals(_) --> { repeat, fail }.", attribute_goals/3).
hook_program("prolog_stack_frame_property(_, _) :- repeat, fail.",
             prolog_stack_frame_property/2).
hook_program("prolog:message(_) --> { repeat, fail }.", message/3).
hook_program("prolog:error_message(_) --> { repeat, fail }.", error_message/3).
hook_program(":- dynamic prolog_exception_hook/4.", prolog_exception_hook/4).
hook_program(":- dynamic user:thread_message_hook/3.", thread_message_hook/3).
hook_program(":- multifile prolog:message//1.", message/3).
hook_program(":- discontiguous attribute_goals//1.", attribute_goals/3).
hook_program("user:(portray(_) :- repeat, fail).", portray/1).
hook_program("sandbox:safe_primitive(system:shell(_)).", safe_primitive/1).
hook_program("safe_primitive(system:shell(_)).", safe_primitive/1).
hook_program("platform_request(x, _, ok(x), true).", platform_request/4).

:- begin_tests(codeload).

test(syntax_error_names_file_and_line, [cleanup(stop_all([N]))]) :-
    node(N, A, []),
    write_program('broken_syntax.pl',
                  [ 'codeload_ok(1).', 'codeload_bad(X) :- X = .', 'codeload_also(2).' ],
                  File),
    catch(load_program_at(A, File, [tokens([7])]), E, true),
    assertion(E = error(load_errors([_]), _)),
    E = error(load_errors([Text]), _),
    assertion(sub_string(Text, 0, _, _, "broken_syntax.pl:2:")),
    assertion(sub_string(Text, _, _, _, "Syntax error")),
    program_module('broken_syntax.pl', M),
    assertion(\+ catch(M:codeload_ok(_), _, fail)).

test(clean_program_loads, [cleanup(stop_all([N]))]) :-
    node(N, A, []),
    write_program('fine.pl', [ 'codeload_fine(1).' ], File),
    load_program_at(A, File, [tokens([7])]),
    program_module('fine.pl', M),
    assertion(M:codeload_fine(1)),
    assertion(\+ current_predicate(user:codeload_fine/1)).

:- end_tests(codeload).

:- begin_tests(program_hooks).

%   One program per hook, each over the connection; the refusal names the
%   hook and nothing of the program loads (its marker fact stays absent).
test(every_hook_refused_by_name, [cleanup(stop_all([N]))]) :-
    node(N, A, []),
    forall(hook_program(Clause, PI),
           ( format(string(Text), "hook_marker(1).~n~w~n", [Clause]),
             send(A, hook, Text, E),
             assertion(subsumes_term(error(permission_error(install, code, hook(_:PI)), _), E)),
             message_to_codes(E, Codes),
             format(string(PIText), "~q", [PI]),
             assertion(sub_string(Codes, _, _, _, PIText)),
             program_module(hook, M),
             assertion(\+ catch(M:hook_marker(_), _, fail)) )),
    send(A, hook, "hook_marker(1).\nmy_portray(_) :- true.\n", Ok),   % control
    assertion(Ok == ok),
    program_module(hook, M),
    assertion(M:hook_marker(1)).

message_to_codes(E, S) :-
    message_to_codes(E, [], Codes0),
    string_codes(S, Codes0).
message_to_codes(E, _, Codes) :-
    '$messages':translate_message(E, Lines, []),
    with_output_to(codes(Codes), print_message_lines(current_output, '', Lines)).

test(library_and_system_names_refused) :-
    forall(member(Text-PI, [ "append(_, _, _)." - append/3,
                             "atom_length(_, _)." - atom_length/2,
                             "safe_meta(_, _)." - safe_meta/2 ]),
           ( catch(check_program_text(names, Text), E, true),
             assertion(subsumes_term(error(permission_error(install, code, hook(_:PI)), _),
                                     E)) )).

%   Looking a name up loads nothing: predicate_property/2 of an
%   undefined name would autoload its library into the node.
test(name_lookup_autoloads_nothing, [condition(\+ current_module(backward_compatibility))]) :-
    catch(check_program_text(names, "merge(_, _, _)."), E, true),
    assertion(subsumes_term(error(permission_error(install, code, hook(_:merge/3)), _), E)),
    assertion(\+ current_module(backward_compatibility)).

test(user_qualified_clause_refused) :-
    catch(check_program_text(q, "user:injected(1)."), E, true),
    assertion(subsumes_term(error(permission_error(install, code, clause_head(user:_)), _),
                            E)).

%   The hooks derived again from the installed SWI-Prolog: every
%   user:Name/Arity and prolog:Name/Arity (or //Arity) its boot/ and
%   library/ sources name, and the user:, prolog: and unqualified entries
%   of library(prolog_xref)'s table of hooks, are refused by name.
test(hooks_derived_from_the_installed_sources) :-
    swi_hooks(Hooks),
    length(Hooks, N),
    assertion(N > 100),
    forall(member(_:F/A, Hooks),
           assertion(code_hooks:hook_refusal(F/A, _, _))).

swi_hooks(Hooks) :-
    current_prolog_flag(home, Home),
    findall(File,
            ( member(Sub, [boot, library]),
              directory_file_path(Home, Sub, Dir),
              directory_member(Dir, File, [recursive(true), extensions([pl])]) ),
            Files),
    findall(Hook,
            ( member(File, Files),
              read_file_to_string(File, Text, []),
              named_hook(Text, Hook) ),
            Named),
    absolute_file_name(library(prolog_xref), Xref, [file_type(prolog), access(read)]),
    read_file_to_string(Xref, XrefText, []),
    split_string(XrefText, "\n", "", Lines),
    findall(Q:F/A,
            ( member(Line, Lines),
              string_concat("hook(", _, Line),
              catch(term_string(hook(H), Line), _, fail),
              (   H = Q:T -> true ; Q = attribute, T = H ),
              memberchk(Q, [user, prolog, attribute]),
              functor(T, F, A) ),
            Listed),
    append(Named, Listed, Hooks0),
    sort(Hooks0, Hooks).

named_hook(Text, Q:F/A) :-
    member(Q, [user, prolog]),
    atom_concat(Q, ':', Prefix),
    sub_string(Text, B, L, _, Prefix),
    P is B + L,
    name_at(Text, P, F, P1),
    (   sub_string(Text, P1, 2, _, "//")
    ->  P2 is P1 + 2, Extra = 2
    ;   sub_string(Text, P1, 1, _, "/")
    ->  P2 is P1 + 1, Extra = 0
    ),
    digits_at(Text, P2, A0),
    A is A0 + Extra.

name_at(Text, P, Name, End) :-
    sub_string(Text, P, 1, _, C0),
    char_type(C0, csymf), \+ char_type(C0, upper), C0 \== "_",
    span(Text, P, csym, End),
    End > P,
    Len is End - P,
    sub_atom(Text, P, Len, _, Name).

digits_at(Text, P, N) :-
    span(Text, P, digit(_), End),
    End > P,
    Len is End - P,
    sub_string(Text, P, Len, _, S),
    number_string(N, S).

span(Text, P, Type, End) :-
    (   sub_string(Text, P, 1, _, C),
        char_type(C, Type)
    ->  P1 is P + 1,
        span(Text, P1, Type, End)
    ;   End = P
    ).

:- end_tests(program_hooks).

:- begin_tests(program_modules).

%   Two peers' programs define the same names: both load, each keeps its
%   own, and an aggregation method of each calls its own helper.
test(same_names_do_not_clash, [cleanup(stop_all([N]))]) :-
    node(N, A, []),
    send(A, prog_a, "shared(a).\nhelper(X, Y) :- Y is X + 1.\n\c
                     dfrl_aggregation:aggregate_init(clash_a, V, W) :- helper(V, W).\n", Ea),
    send(A, prog_b, "shared(b).\nhelper(X, Y) :- Y is X * 10.\n\c
                     dfrl_aggregation:aggregate_init(clash_b, V, W) :- helper(V, W).\n", Eb),
    assertion(Ea == ok),
    assertion(Eb == ok),
    program_module(prog_a, Ma),
    program_module(prog_b, Mb),
    assertion(Ma:shared(a)),
    assertion(\+ Ma:shared(b)),
    assertion(Mb:shared(b)),
    assertion(\+ current_predicate(user:shared/1)),
    assertion(dfrl_aggregation:aggregate_init(clash_a, 2, 3)),
    assertion(dfrl_aggregation:aggregate_init(clash_b, 2, 20)),
    send(A, prog_a, "shared(a2).\n", Ea2),                  % a reload replaces prog_a only
    assertion(Ea2 == ok),
    assertion(Ma:shared(a2)),
    assertion(\+ Ma:shared(a)),
    assertion(\+ dfrl_aggregation:aggregate_init(clash_a, _, _)),
    assertion(Mb:shared(b)).

%   A program cannot take a name the node defines in user for another.
test(node_names_refused) :-
    catch(check_program_text(n, "stop_all(_)."), E, true),
    assertion(subsumes_term(error(permission_error(install, code, hook(user:stop_all/1)), _),
                            E)).

:- end_tests(program_modules).

:- begin_tests(program_initialization).

test(init_runs_after_load, [cleanup(stop_all([N]))]) :-
    node(N, A, []),
    send(A, init_ok, ":- initialization(assertz(init_seen(1))).\n:- dynamic init_seen/1.\n\c
                      :- initialization(init_seen(1), now).\n", E),
    assertion(E == ok),
    program_module(init_ok, M),
    assertion(M:init_seen(1)).

%   An error in an initialization goal is a load error of the program,
%   which stays loaded (as a file whose initialization raised).
test(init_error_is_a_load_error, [cleanup(stop_all([N]))]) :-
    node(N, A, []),
    send(A, init_err, "err_marker(1).\n:- initialization(atom_length(1, a)).\n", E),
    assertion(subsumes_term(error(load_errors([_]), _), E)),
    program_module(init_err, M),
    assertion(M:err_marker(1)).

%   A loop in initialization is stopped by the CPU bound; the program is
%   taken out again and the node takes an ordinary program afterwards.
test(init_loop_stopped_by_cpu, [cleanup(stop_all([N]))]) :-
    node(N, A, [agent_cpu_limit(0.5)]),
    forall(member(Text, [ "loop_marker(1).\n:- initialization((repeat, fail)).\n",
                          "loop_marker(1).\n?- initialization((repeat, fail)).\n",
                          "loop_marker(1).\n:- dynamic(d/1), initialization((repeat, fail), now).\n"
                        ]),
           ( get_time(T0),
             send(A, init_loop, Text, E),
             get_time(T1),
             assertion(subsumes_term(error(resource_error(program_initialization(init_loop,
                                                                                 cpu(_))), _),
                                     E)),
             assertion(T1 - T0 < 8),
             program_module(init_loop, M),
             assertion(\+ catch(M:loop_marker(_), _, fail)) )),
    send(A, after_loop, "after(1).\n", Ok),
    assertion(Ok == ok).

%   A loop that sleeps takes no CPU: the wall clock stops it.
test(init_sleep_loop_stopped_by_wall_clock, [cleanup(stop_all([N]))]) :-
    node(N, A, [agent_cpu_limit(0.2)]),                 % wall clock: 5 x 0.2 s
    send(A, init_sleep, ":- initialization((repeat, sleep(0.05), fail)).\n", E),
    assertion(subsumes_term(error(resource_error(program_initialization(init_sleep,
                                                                        wall_time(1.0))), _),
                            E)).

test(init_memory_stopped_by_stack_bound, [cleanup(stop_all([N]))]) :-
    node(N, A, [agent_stack_limit(33554432)]),
    send(A, init_mem, ":- initialization(numlist(1, 100000000, _)).\n", E),
    assertion(subsumes_term(error(resource_error(program_initialization(init_mem,
                                                                        memory(_))), _),
                            E)).

:- end_tests(program_initialization).
