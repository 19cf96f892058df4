/*  plunit tests of codeload.pl: a program a peer sends with a syntax error
    is refused as a whole and the error names the program, line and column
    (issue 20), on a real node over a real connection.
    Run: swipl -g run_tests -t halt test_codeload.pl
*/
:- use_module('../../platform_pl/tartarus').
:- use_module('../../platform_pl/codeload').
:- use_module(library(plunit)).

stop_all(Nodes) :- forall(member(N, Nodes), catch(node_stop(N), _, true)).

write_program(Name, Lines, Path) :-
    tmp_file(codeload, Dir),
    make_directory(Dir),
    directory_file_path(Dir, Name, Path),
    setup_call_cleanup(open(Path, write, Out),
                       forall(member(L, Lines), format(Out, "~w~n", [L])),
                       close(Out)).

:- begin_tests(codeload).

test(syntax_error_names_file_and_line, [cleanup(stop_all([N]))]) :-
    node_start('127.0.0.1':0, N, [default(false), token(7)]),
    node_property(N, address(A)),
    write_program('broken_syntax.pl',
                  [ 'codeload_ok(1).', 'codeload_bad(X) :- X = .', 'codeload_also(2).' ],
                  File),
    catch(load_program_at(A, File, [tokens([7])]), E, true),
    assertion(E = error(load_errors([_]), _)),
    E = error(load_errors([Text]), _),
    assertion(sub_string(Text, 0, _, _, "broken_syntax.pl:2:")),
    assertion(sub_string(Text, _, _, _, "Syntax error")),
    assertion(\+ catch(user:codeload_ok(_), _, fail)).

test(clean_program_loads, [cleanup(stop_all([N]))]) :-
    node_start('127.0.0.1':0, N, [default(false), token(7)]),
    node_property(N, address(A)),
    write_program('fine.pl', [ 'codeload_fine(1).' ], File),
    load_program_at(A, File, [tokens([7])]),
    assertion(user:codeload_fine(1)).

:- end_tests(codeload).
