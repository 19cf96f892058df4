/*  plunit tests of guest_limits.pl (issue 32): sizes of work done in C
    checked before the call, reached by every way guest code has to the
    built-ins (direct calls, meta-calls, lambdas, programs), refused at
    install when known then; each with a control of the same code at a
    small size that runs and gives the right result.
*/
:- use_module('../../platform_pl/tartarus').
:- use_module('../../platform_pl/code_safety').
:- use_module('../../platform_pl/codeload').
:- use_module('../../platform_pl/guest_limits', [guest_module_init/1, guest_static_refusal/2]).
:- use_module(library(plunit)).
:- use_module(library(yall)).
:- use_module(library(apply)).

%   An agent-like module: clauses asserted after guest_module_init/1, as
%   agents.pl installs an arriving agent's.
guest(M) :-
    M = 'dfrl_agent@test/g1',
    guest_module_init(M).

run(Clause, Result) :-
    guest(M),
    Clause = (Head :- _),
    functor(Head, F, A),
    functor(H0, F, A),
    retractall(M:H0),
    assertz(M:Clause),
    catch(( M:Head -> Result = Head ; Result = failed ), E, Result = E).

too_big(error(resource_error(guest_integer), _)).
too_big(error(resource_error(guest_text), _)).

:- begin_tests(resolution).

test(direct_call) :-
    run((t(X) :- X is 7^400000000), R), assertion(too_big(R)).
test(call_n) :-
    run((t(X) :- call(is, X, 7^400000000)), R), assertion(too_big(R)).
test(maplist_closure) :-
    run((t(X) :- maplist(is, [X], [7^400000000])), R), assertion(too_big(R)).
test(yall_lambda) :-
    run((t(X) :- maplist([E, V]>>(V is E), [7^400000000], [X])), R), assertion(too_big(R)).
test(findall_goal) :-
    run((t(L) :- findall(X, X is 7^400000000, L)), R), assertion(too_big(R)).
test(foldl_lambda) :-
    run((t(X) :- foldl([E, A0, A]>>(A is A0*E), [7^400000000], 1, X)), R),
    assertion(too_big(R)).
test(data_goal) :-
    run((t(X) :- G = (X is 7^400000000), call(G)), R), assertion(too_big(R)).
test(comparison) :-
    run((t(_) :- 3 < 7^400000000), R), assertion(too_big(R)).
test(shift) :-
    run((t(X) :- X is 1 << 100000000), R), assertion(too_big(R)).
test(library_sum) :-
    run((t(S) :- sum_list([7^400000000], S)), R), assertion(too_big(R)).
test(aggregate_sum) :-
    run((t(S) :- aggregate_all(sum(X), member(X, [7^400000000]), S)), R),
    assertion(too_big(R)).
test(control_arithmetic) :-
    run((t([X, Y, Z, W, P]) :- X is 7^100 mod 1000, Y is 2**10 + 3 << 4,
                               Z is 10/4, W is max(3, 4.0), P is powm(3, 1000, 1000007)), R),
    V is 7^100 mod 1000,
    assertion(R == t([V, 1072, 2.5, 4.0, 297623])).
test(control_meta) :-
    run((t([L1, L2, S]) :- maplist(is, L1, [1+1, 2*3]), findall(Y, Y is 2+3, L2),
                           foldl([E, A0, A]>>(A is A0+E), [1, 2, 3], 0, S)), R),
    assertion(R == t([[2, 6], [5], 6])).

:- end_tests(resolution).

:- begin_tests(text).

test(format_star) :-
    run((t(A) :- format(atom(A), "~*c", [400000000, 0'x])), R), assertion(too_big(R)).
test(format_column) :-
    run((t(A) :- N = 400000000, format(atom(A), "~t~*|", [N])), R), assertion(too_big(R)).
test(format_precision) :-
    run((t(A) :- format(atom(A), "~400000000e", [1.0])), R), assertion(too_big(R)).
test(atomic_list_concat) :-
    run((t(A) :- format(atom(B), "~*c", [5000000, 0'x]), length(L, 100),
                 maplist(=(B), L), atomic_list_concat(L, A)), R),
    assertion(too_big(R)).
test(doubling) :-
    run((t(A) :- numlist(1, 30, Ks), foldl([_, A0, A1]>>atom_concat(A0, A0, A1), Ks, x, A)), R),
    assertion(too_big(R)).
test(shared_subterms) :-                % written size exponential in the stacks' size
    run((t(S) :- numlist(1, 40, Ks), foldl([_, T0, f(T0, T0)]>>true, Ks, x, T),
                 term_to_atom(T, S)), R),
    assertion(too_big(R)).
test(write_length_shared) :-           % writes to nowhere, in exponential time
    run((t(L) :- numlist(1, 60, Ks), foldl([_, T0, f(T0, T0)]>>true, Ks, x, T),
                 write_length(T, L, [])), R),
    assertion(too_big(R)).
test(tab) :-
    run((t(_) :- with_output_to(string(_), tab(400000000))), R), assertion(too_big(R)).
test(control_text) :-
    run((t([L1, L2, L3, S]) :- format(atom(A), "~*c~t~20|", [10, 0'x]), atom_length(A, L1),
                               length(Xs, 100), maplist(=(abcdefghij), Xs),
                               atomic_list_concat(Xs, B), atom_length(B, L2),
                               numlist(1, 10, Ks),
                               foldl([_, A0, A1]>>atom_concat(A0, A0, A1), Ks, x, C),
                               atom_length(C, L3), term_to_atom(f(x, "y"), S0),
                               write_length(S0, L4, []), S = S0-L4), R),
    assertion(R == t([20, 1000, 1024, 'f(x,"y")'-8])).

%   A with_output_to/2 sink filled write by write: each write is small,
%   the text they make together is not (checked before each write, not
%   by the RSS monitor's tick). Nested sinks, explicit streams, format
%   and tab alike; the control writes the same way within the limit.
test(sink_write_by_write, [forall(member(B-W, [ B-write(B), B-print(B), B-writeln(B),
                                                B-format("~w", [B]),
                                                _-format("~*c", [1000000, 0'z]),
                                                B-(current_output(O), write(O, B)),
                                                B-(current_output(O), format(O, "~a", [B])),
                                                _-tab(1000000),
                                                B-(with_output_to(string(_), write(x)), write(B))
                                              ]))]) :-
    run((t(L) :- format(atom(B), "~*c", [1000000, 0'z]),
                 with_output_to(string(S), forall(between(1, 20, _), W)),
                 string_length(S, L)), R),
    assertion(too_big(R)).
test(sink_nested_outer_counts) :-
    run((t(L) :- format(atom(B), "~*c", [1000000, 0'z]),
                 with_output_to(string(S),
                                ( forall(between(1, 5, _), write(B)),
                                  with_output_to(string(_), write(x)),
                                  forall(between(1, 5, _), write(B)) )),
                 string_length(S, L)), R),
    assertion(too_big(R)).
test(sink_control) :-
    run((t([L, L2]) :- format(atom(B), "~*c", [1000000, 0'z]),
                       with_output_to(string(S), forall(between(1, 8, _), write(B))),
                       string_length(S, L),
                       with_output_to(string(S2), forall(between(1, 8, _), write(B))),
                       string_length(S2, L2)), R),
    assertion(R == t([8000000, 8000000])).

:- end_tests(text).

:- begin_tests(install).

record(Body, agent(a1, h, mobile, [], [], [], [(h(a1, _, main) :- Body)], [])).

refused(Body, Why) :-
    record(Body, R),
    catch(check_agent_record(R),
          error(permission_error(install, code, _), context(_, Why)), true),
    atom(Why).

test(literal_sizes_refused, [forall(member(B, [ format(atom(_), "~*c", [400000000, 0'x]),
                                               (_ is 7^400000000),
                                               format(atom(_), "~t~400000000|", []),
                                               tab(400000000) ]))]) :-
    refused(B, Why),
    assertion(sub_atom(Why, _, _, _, over)).
test(explicit_module_refused, [forall(member(B, [ system:is(_, 7),
                                                 call(system:is, _, 7),
                                                 apply:maplist(is, [_], [1]),
                                                 lists:sum_list([1], _),
                                                 aggregate:aggregate_all(sum(X), member(X, [1]), _) ]))]) :-
    refused(B, Why),
    assertion(sub_atom(Why, _, _, _, 'skips the size checks')).
test(control_accepted) :-
    record(( N = 10, X is 7^3, format(atom(A), "~w ~*c", [X, N, 0'x]), atom_length(A, _),
             maplist(is, [_], [1+2]), sum_list([1, 2], _), numlist(1, 3, L), nth0(1, L, _) ), R),
    check_agent_record(R).
test(static_refusal_says_why) :-
    guest_static_refusal(format(atom(_), "~*c", [400000000, 0'x]), Why),
    assertion(sub_atom(Why, _, _, _, dfrl_guest_text_limit)),
    assertion(\+ guest_static_refusal(format(atom(_), "~*c", [_, 0'x]), _)).

:- end_tests(install).

:- begin_tests(programs).

program("
gl_p1(X) :- X is 7^400000000.
gl_p2(X) :- C = is, call(C, X, 7^400000000).
gl_p3(X) :- foldl([E,A0,A]>>(A is A0*E), [7^400000000], 1, X).
gl_p4(X) :- G = (Y = 7^400000000, X is Y), forall(G, true).
gl_p5(A) :- N = 400000000, format(atom(A), \"~*c\", [N, 0'x]).
gl_p6(L) :- format(atom(B), \"~*c\", [1000000, 0'z]),
    with_output_to(string(S), forall(between(1, 20, _), write(B))), string_length(S, L).
gl_ok(X) :- G = (Y is 2+3), findall(Y, G, [Z]), maplist([A,B]>>(B is A*2), [Z], [X]).
").

%   A program a peer sent loads into a module of its own (codeload.pl),
%   rewritten while it loads; it has no initialization goals, so no node
%   is needed to run them.
program_loaded(M) :-
    codeload:program_module(gl, M),
    (   current_predicate(M:gl_ok/1) -> true ; program(T), codeload:load_text(none, gl, T) ).

test(program_goals_checked, [forall(member(G, [gl_p1(_), gl_p2(_), gl_p3(_), gl_p4(_), gl_p5(_),
                                                   gl_p6(_)]))]) :-
    program_loaded(M),
    catch(M:G, E, true),
    assertion(too_big(E)).
test(program_control) :-
    program_loaded(M),
    M:gl_ok(X),
    assertion(X == 10).

:- end_tests(programs).
